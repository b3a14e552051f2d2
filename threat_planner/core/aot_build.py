"""Build the ahead-of-time kernel module (numba.pycc) of these sources into the cache.

Run by :func:`.compiled.compile_all` in a child process with ``THREAT_PLANNER_AOT=0``
(``python -m threat_planner.core.aot_build``), after the JIT workload wrote the signature
manifest; the build rebinds the kernel modules' dispatchers, which no planning process
may see. Sources stay single: every export is the ``py_func`` of the same ``@njit``
kernel. Steps:

1. load each Python-called kernel (:data:`._aot.ENTRY`) once with the manifest's
   signature, from the JIT cache, to learn its return type;
2. replace every kernel dispatcher of the kernel modules by a fresh, uncached one with
   the same options minus ``parallel`` (pycc cannot launch numba's threading layer) and
   ``cache`` (the callees are linked in as LLVM IR: cached object code must not be used);
3. export each entry's py_func with its full signature, compile into a temporary folder,
   import the result, then move it and its stamp (digest, tag, signatures) into
   :func:`._aot.aot_dir` at once, so a half-built module is never found.

It took 54-60 s on 2 shared cores (1-3 s of it the signatures).
"""

from __future__ import annotations

import importlib
import json
import os
from pathlib import Path
import shutil
import sys
import tempfile
import time

from threat_planner.core import _aot


def build(outdir: Path | None = None) -> str:
    """Build the module into `outdir` (default :func:`._aot.aot_dir`); return a report line."""
    t0 = time.perf_counter()
    if _aot.active():
        raise RuntimeError('run with THREAT_PLANNER_AOT=0 (this process uses the AOT kernels)')
    from numba import njit
    from numba.core.dispatcher import Dispatcher
    from numba.pycc import CC
    from threat_planner.core import _numba_cache, compiled
    sigs = compiled._read_manifest()
    if not sigs:
        raise RuntimeError('no signature manifest: the JIT workload did not run')
    disp = compiled._dispatchers()
    full = {}
    for qual in _aot.quals():
        d = disp[qual]
        if len(sigs.get(qual, ())) != 1:
            raise RuntimeError(f'{qual}: {len(sigs.get(qual, ()))} signatures, 1 expected')
        d.compile(sigs[qual][0])
        full[qual] = d.overloads[sigs[qual][0]].signature
    fresh = {}
    for d in disp.values():
        opts = {k: v for k, v in d.targetoptions.items() if k not in ('parallel', 'cache')}
        fresh[id(d)] = njit(**opts)(d.py_func)
    for modname in compiled.KERNEL_MODULES:
        ns = vars(importlib.import_module(modname))
        for attr, value in list(ns.items()):
            if isinstance(value, Dispatcher) and id(value) in fresh:
                ns[attr] = fresh[id(value)]
    final = Path(outdir) if outdir else _aot.aot_dir()
    final.parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix='.build-', dir=final.parent))
    try:
        cc = CC(_aot.MODULE_NAME)
        cc.output_dir = str(work)
        cc.verbose = False
        cc.target_cpu = 'host'  # as the JIT; the folder's tag names the CPU (_aot.cpu_id)
        for qual, sig in full.items():
            cc.export(_aot.symbol(qual), sig)(disp[qual].py_func)
        cc.compile()
        stamp = {'digest': _numba_cache.sources_digest(), 'tag': _aot.tag(),
                 'signatures': {_aot.symbol(q): [str(t) for t in s.args]
                                for q, s in full.items()}}
        (work / _aot.STAMP).write_text(json.dumps(stamp, indent=1))
        module, why = _aot.load(work)
        if module is None:
            raise RuntimeError(why)
        old = final.with_name(final.name + f'.old-{os.getpid()}')
        if final.exists():
            final.rename(old)
        work.rename(final)
        shutil.rmtree(old, ignore_errors=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return (f'built the AOT kernels ({len(full)} exports) in {time.perf_counter() - t0:.0f} s '
            f'into {final}')


def main() -> int:
    """Build, print one line; exit status 1 with the reason in that line on failure."""
    try:
        print(build(Path(sys.argv[1]) if len(sys.argv) > 1 else None))
        return 0
    except Exception as exc:  # noqa: BLE001 - any failure: the JIT path stays
        print(f'{type(exc).__name__}: {exc}'.splitlines()[0][:300])
        return 1


if __name__ == '__main__':
    sys.exit(main())
