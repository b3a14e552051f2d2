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

It took 44-60 s on 2 shared cores (1-3 s of it the signatures). Given the signatures of
:mod:`._aot_signatures` (``--committed``), step 1 reads them instead of the manifest and the
JIT cache, so :func:`.compiled.compile_all` runs the build beside the JIT workload and
keeps its module only if the workload's signatures are those (``--signatures`` prints
that module for the current manifest).
"""

from __future__ import annotations

import importlib
import json
from pathlib import Path
import shutil
import sys
import tempfile
import time

from threat_planner.core import _aot


def _split(text: str) -> list[str]:
    """Split `text` at the commas outside brackets."""
    parts, depth, start = [], 0, 0
    for i, ch in enumerate(text):
        depth += (ch == '(') - (ch == ')')
        if ch == ',' and depth == 0:
            parts.append(text[start:i].strip())
            start = i + 1
    return parts + [text[start:].strip()]


def parse_type(text: str):
    """Return the numba type whose ``str`` is `text` (the kinds the exports use)."""
    from numba.core import types
    readonly = text.startswith('readonly ')
    body = text[len('readonly '):] if readonly else text
    if body.startswith('array(') and body.endswith(')'):
        dtype, ndim, layout = _split(body[6:-1])
        return types.Array(parse_type(dtype), int(ndim.rstrip('d')), layout, readonly=readonly)
    if body.startswith('UniTuple(') and body.endswith(')'):
        item, count = body[9:-1].rsplit(' x ', 1)
        return types.UniTuple(parse_type(item), int(count))
    if body.startswith('Tuple(') and body.endswith(')'):
        return types.Tuple([parse_type(t) for t in _split(body[6:-1])])
    scalar = {'bool': types.boolean, 'none': types.none}.get(body, getattr(types, body, None))
    if not isinstance(scalar, types.Type) or str(scalar) != text:
        raise ValueError(f'not a type the exports use: {text!r}')
    return scalar


def build(outdir: Path | None = None, signatures: dict | None = None) -> str:
    """Build the module into `outdir` (default :func:`._aot.aot_dir`); return a report line.

    ``signatures`` (as :func:`.compiled.export_signatures` returns them) replace the manifest's.
    """
    t0 = time.perf_counter()
    if _aot.active():
        raise RuntimeError('run with THREAT_PLANNER_AOT=0 (this process uses the AOT kernels)')
    from numba import njit
    from numba.core.dispatcher import Dispatcher
    from numba.core.typing import signature
    from numba.pycc import CC
    from threat_planner.core import _numba_cache, compiled
    described = compiled.export_signatures() if signatures is None else signatures
    disp = compiled._dispatchers()
    full = {qual: signature(parse_type(ret), *(parse_type(t) for t in args))
            for qual, (ret, args) in described.items()}
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
        _aot.move_into_place(work, final)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return (f'built the AOT kernels ({len(full)} exports) in {time.perf_counter() - t0:.0f} s '
            f'into {final}')


#: Short names of the common types in the printed :mod:`._aot_signatures`.
_ALIASES = {'F8': 'float64', 'I8': 'int64', 'B1': 'bool', 'NONE': 'none',
            'A1': 'array(float64, 1d, C)', 'A2': 'array(float64, 2d, C)',
            'A3': 'array(float64, 3d, C)', 'R1': 'readonly array(float64, 1d, C)',
            'R2': 'readonly array(float64, 2d, C)', 'I1': 'array(int64, 1d, C)'}


def signatures_module(sigs: dict) -> str:
    """Return the text of :mod:`._aot_signatures` for `sigs`."""
    import textwrap
    short = {v: k for k, v in _ALIASES.items()}
    lines = ['"""Signatures of the AOT exports, for building the module beside the JIT '
             'workload.', '', 'Written by ``python -m threat_planner.core.aot_build '
             '--signatures``; a test checks', 'them against the workload\'s. Each: '
             '(return type, argument types), as numba prints them.', '"""', '']
    lines += [f'{k} = {v!r}' for k, v in _ALIASES.items()]
    lines += ['', 'SIGNATURES = {']
    for qual, (ret, args) in sigs.items():
        names = ', '.join(short.get(t, repr(t)) for t in args) + (',' if len(args) == 1 else '')
        body = f'({short.get(ret, repr(ret))}, ({names})),'
        lines.append(f'    {qual!r}:')
        lines += textwrap.wrap(body, 95, initial_indent='        ',
                               subsequent_indent='         ')
    return '\n'.join(lines + ['}', ''])


def main(argv: list[str] | None = None) -> int:
    """Build, print one line; exit status 1 with the reason in that line on failure.

    ``[OUTDIR] [--committed]``: build into OUTDIR from :mod:`._aot_signatures`' signatures;
    ``--signatures``: print that module for this cache's manifest instead.
    """
    args = sys.argv[1:] if argv is None else argv
    try:
        if '--signatures' in args:
            from threat_planner.core.compiled import export_signatures
            print(signatures_module(export_signatures()), end='')
            return 0
        sigs = None
        if '--committed' in args:
            from threat_planner.core._aot_signatures import SIGNATURES as sigs
        outdir = next((Path(a) for a in args if not a.startswith('--')), None)
        print(build(outdir, sigs))
        return 0
    except Exception as exc:  # noqa: BLE001 - any failure: the JIT path stays
        print(f'{type(exc).__name__}: {exc}'.splitlines()[0][:300])
        return 1


if __name__ == '__main__':
    sys.exit(main())
