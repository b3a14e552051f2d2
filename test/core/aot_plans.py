"""Plan a representative set and print J and paths as JSON (run by test_aot*.py).

``python aot_plans.py [--check]``: with ``--check`` every exported AOT kernel is wrapped
in a shim comparing ``numba.typeof`` of each argument with the signature the module was
built for, and every other kernel function in one that records a call from Python (it
would run as plain Python on the AOT path). The bundled scenarios at w 0.2/0.5/0.8,
limits on and off, warm replans of moved threats (uniform20_0, air_mixed_0), the
airspace scenarios at w 0.5 without limits; the 300-threat one (the parallel paths)
without limits at w 0.5, last.
"""

import glob
import json
import os
import sys

import numpy as np

from threat_planner.core import _aot, load_scenario, plan, PlannerConfig, ThreatField
from threat_planner.core.inputs.settings import NO_LIMITS

DATA = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'data')
BAD: list = []
SEEN: dict = {}


def _layout(a):
    """Return what numba.typeof of `a` depends on, without numba."""
    if isinstance(a, np.ndarray):
        f = a.flags
        return ('array', a.dtype.str, a.ndim, f.c_contiguous, f.f_contiguous, f.writeable,
                f.aligned)
    if isinstance(a, tuple):
        return ('tuple',) + tuple(_layout(x) for x in a)
    return type(a).__name__


def _check_types() -> None:
    import numba
    for (name, _), (args, want) in SEEN.items():
        got = [str(numba.typeof(a)) for a in args]
        if got != want:
            BAD.append([name, [(i, g, w) for i, (g, w) in enumerate(zip(got, want))
                               if g != w] or [len(got), len(want)]])


def _install_shim() -> int:
    stamp = json.loads((_aot.aot_dir() / _aot.STAMP).read_text())['signatures']
    exported = {}
    for qual in _aot.quals():
        fn = _aot.REGISTRY[qual][0]
        mod = sys.modules[fn.__module__]
        exported[id(vars(mod)[fn.__name__])] = (_aot.symbol(qual), stamp[_aot.symbol(qual)])
    others = {id(fn): qual for qual, (fn, _) in _aot.REGISTRY.items() if qual not in
              _aot.quals()}

    def checking(fn, name, want):
        def shim(*args):
            # numba.typeof at the end (numba not imported while planning): one example
            # of each distinct argument layout is kept.
            SEEN.setdefault((name, tuple(_layout(a) for a in args)), (args, want))
            return fn(*args)
        return shim

    def python_call(fn, qual):
        def shim(*args, **kwargs):
            BAD.append([qual, 'a kernel that is not exported called from Python'])
            return fn(*args, **kwargs)
        return shim

    n = 0
    for modname, mod in list(sys.modules.items()):
        if not modname.startswith('threat_planner') or mod is None:
            continue
        ns = vars(mod)
        for attr, value in list(ns.items()):
            if id(value) in exported:
                ns[attr] = checking(value, *exported[id(value)])
                n += 1
            elif id(value) in others:
                ns[attr] = python_call(value, others[id(value)])
    return n


def runs():
    """Yield (name, scenario, config, warm): the representative set."""
    for f in sorted(glob.glob(os.path.join(DATA, '*.yaml'))):
        sc = load_scenario(f)
        name = os.path.basename(f)
        if len(sc.threats) >= 100:
            continue
        # The airspace plans (SLSQP in Python, 0.4-8 s each) took 80 of the set's 88 s at
        # three weights, and 27 of 29 s at one with the limits on and off. They call 4-5
        # kernels, each with argument layouts the other plans pass too (measured with
        # --check), so one plan each: w 0.5, limits off (the faster, 9.6 of the 27 s).
        for w in (0.5,) if sc.airspace else (0.2, 0.5, 0.8):
            for limits in ('off',) if sc.airspace else ('on', 'off'):
                extra = {} if limits == 'on' else dict(NO_LIMITS)
                yield f'{name} w{w} {limits}', sc, PlannerConfig(w=w, **extra), \
                    name in ('uniform20_0.yaml', 'air_mixed_0.yaml')
    sc = load_scenario(os.path.join(DATA, 'uniform20_0.yaml'))
    for method in ('paper', 'improved'):
        yield f'uniform20_0 {method}', sc, PlannerConfig(method=method), False
    yield 'NUMBA CHECKPOINT', None, None, False
    sc = load_scenario(os.path.join(DATA, 'big300_0.yaml'))
    yield 'big300_0 w0.5 off', sc, PlannerConfig(w=0.5, **NO_LIMITS), False


def main() -> None:
    """Plan every run; print {'status', 'shims', 'bad', 'numba_small', 'plans'} as JSON."""
    shims = _install_shim() if '--check' in sys.argv else 0
    out, numba_small = {}, None
    for name, sc, cfg, warm in runs():
        if sc is None:
            numba_small = 'numba' in sys.modules
            continue
        r = plan(sc.threats, sc.start, sc.goal, sc.box, cfg, airspace=sc.airspace)
        out[name] = [repr(r.cost.J), np.asarray(r.path).tolist()]
        if warm:
            moved = ThreatField.from_arrays(sc.threats.positions + 1.0, sc.threats.intensities)
            r2 = plan(moved, sc.start, sc.goal, sc.box, cfg, warm_start=r, airspace=sc.airspace)
            out[name + ' warm'] = [repr(r2.cost.J), np.asarray(r2.path).tolist()]
    if shims:
        _check_types()
    print(json.dumps({'status': _aot.status(), 'active': _aot.active(), 'shims': shims,
                      'bad': BAD, 'checked': len(SEEN), 'numba_small': numba_small, 'plans': out}))


if __name__ == '__main__':
    main()
