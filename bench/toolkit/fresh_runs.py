"""Plans of two checkouts for ``python -m bench fresh``, graded in this process.

* :func:`baseline_tree`: a git revision as a worktree under /tmp (an existing clean one of
  the same commit is reused).
* :class:`Worker`: one long-lived process per checkout (``PYTHONPATH`` = that checkout,
  :data:`bench.toolkit.checkouts.THEN_BENCH`) that plans each case it reads as a JSON line
  on stdin with that checkout's public ``plan`` and writes its own J, feasibility, plan
  time and path.
* :func:`grade`: the J and feasibility of any path by this checkout's closed form and the
  bench's independent limit check, so that neither checkout grades itself.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from pathlib import Path
import subprocess
import sys
import time

import numpy as np

from bench.toolkit.checkouts import THEN_BENCH
from bench.toolkit.flight_limits import check_limits, Limits
from bench.toolkit.fresh_fields import Field

_SERVE = THEN_BENCH + 'from bench.toolkit.fresh_runs import serve\nserve()\n'


def _git(tree: Path, *args: str) -> str:
    done = subprocess.run(['git', '-C', str(tree), *args], capture_output=True, text=True)
    return done.stdout.strip() if done.returncode == 0 else ''


def newest_tag(root: Path) -> str:
    """Return the newest release tag of the repository ('' when it has none)."""
    tag = _git(root, 'describe', '--tags', '--abbrev=0')
    if not tag:
        tags = _git(root, 'tag', '--sort=-creatordate').splitlines()
        tag = tags[0] if tags else ''
    return tag


def baseline_tree(root: Path, rev: str) -> tuple[Path, str]:
    """Return a worktree of ``rev`` and its full commit, made under /tmp if none is.

    A worktree of the same commit with no changes to tracked files is reused.

    Raises
    ------
    ValueError
        If ``rev`` names no commit, or the worktree cannot be made.
    """
    commit = _git(root, 'rev-parse', '--verify', '--quiet', f'{rev}^{{commit}}')
    if not commit:
        raise ValueError(f'--baseline {rev}: not a commit of {root}')
    tree = None
    for block in _git(root, 'worktree', 'list', '--porcelain').split('\n\n'):
        fields = dict(line.partition(' ')[::2] for line in block.splitlines())
        path = Path(fields.get('worktree', ''))
        if (fields.get('HEAD') == commit and path.is_dir() and path.resolve() != root
                and not _git(path, 'status', '--porcelain', '--untracked-files=no')):
            tree = path
            break
    if tree is None:
        tree = Path(f'/tmp/fresh_base_{commit[:10]}')
        done = subprocess.run(['git', '-C', str(root), 'worktree', 'add', '--detach',
                               str(tree), commit], capture_output=True, text=True)
        if done.returncode != 0:
            raise ValueError(f'git worktree add {tree} {commit[:10]}: {done.stderr.strip()}')
    return tree, commit


def tree_state(tree: Path) -> str:
    """Return ``commit`` of a checkout, with a digest of any change to its package.

    HEAD means the working tree: a run beside edits to ``threat_planner/`` says so.
    """
    commit = _git(tree, 'rev-parse', '--short', 'HEAD')
    diff = _git(tree, 'diff', 'HEAD', '--', 'threat_planner')
    if not diff:
        return commit
    return f'{commit}+changes (diff {hashlib.sha1(diff.encode()).hexdigest()[:8]})'


def serve() -> None:
    """Plan every JSON case read from stdin with this process's package; one line each."""
    import threat_planner
    from threat_planner import Box, plan, PlannerConfig, ThreatField
    print(json.dumps({'ready': True, 'package': threat_planner.__file__}), flush=True)
    for line in sys.stdin:
        case = json.loads(line)
        field = case['field']
        threats = ThreatField.from_arrays(np.array(field['positions']),
                                          np.array(field['intensities']))
        box = Box.from_corners(field['lo'], field['hi'])
        cfg = PlannerConfig(w=case['w'], **case['limits'])
        t0 = time.perf_counter()
        try:
            r = plan(threats, field['start'], field['goal'], box, cfg)
            out = {'J': r.cost.J, 'feasible': bool(r.feasible),
                   'path': np.asarray(r.path).tolist()}
        except Exception as exc:  # noqa: BLE001 - a failed plan is a row of the report
            out = {'error': f'{type(exc).__name__}: {exc}'}
        out['ms'] = 1e3 * (time.perf_counter() - t0)
        print(json.dumps(out), flush=True)


class Worker:
    """A planning process on one checkout.

    Parameters
    ----------
    tree : Path
        The checkout whose ``threat_planner`` plans.
    """

    def __init__(self, tree: Path) -> None:
        self.tree = Path(tree).resolve()
        self._start()

    def _start(self) -> None:
        env = dict(os.environ, PYTHONPATH=str(self.tree))
        self.proc = subprocess.Popen([sys.executable, '-c', _SERVE], env=env, text=True,
                                     cwd=self.tree, stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE)
        package = json.loads(self.proc.stdout.readline())['package']
        # A worker that imported another checkout's package would compare nothing.
        if not package.startswith(str(self.tree)):
            raise RuntimeError(f'{self.tree}: the worker imported {package}')

    def plan(self, field: Field, w: float, limits: dict) -> dict:
        """Plan one case; its own ``J``, ``feasible``, ``ms`` and ``path`` (or ``error``)."""
        self.proc.stdin.write(json.dumps({'field': field.as_json(), 'w': w,
                                          'limits': limits}) + '\n')
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if line:
            return json.loads(line)
        # The process died (a crash in compiled code): a row saying so, and a new worker.
        code = self.proc.wait()
        self._start()
        return {'error': f'worker exited with status {code}', 'ms': math.nan}

    def close(self) -> None:
        """End the worker (its input closed)."""
        self.proc.stdin.close()
        self.proc.wait(timeout=60)


def grade(path: object, field: Field, w: float, limits: dict) -> dict:
    """Return the exact J and the independent feasibility of a path.

    Parameters
    ----------
    path : array_like, shape (m, 3), or None
        The path [m]; None for a plan that failed.
    field : Field
        The problem.
    w : float
        Threat weight.
    limits : dict
        ``max_climb_deg``, ``max_dive_deg``, ``min_turn_radius_m`` in force.

    Returns
    -------
    dict
        ``J`` (this checkout's ``path_cost``; inf for no path) and ``feasible``: the end
        points are the field's, every vertex is inside the box, J is finite and
        :func:`bench.toolkit.flight_limits.check_limits` passes; ``why`` names a failure.
    """
    from threat_planner.core.cost.closed_form import path_cost
    if path is None:
        return {'J': math.inf, 'feasible': False, 'why': 'no path'}
    p = np.asarray(path, float)
    tol = 1e-9 * max(float(np.linalg.norm(field.hi - field.lo)), 1.0)
    j = float(path_cost(p, field.positions, field.intensities, w).J)
    why = []
    if not (np.allclose(p[0], field.start, rtol=0, atol=tol)
            and np.allclose(p[-1], field.goal, rtol=0, atol=tol)):
        why.append('end points moved')
    if np.any(p < field.lo - tol) or np.any(p > field.hi + tol):
        why.append('leaves the box')
    if not math.isfinite(j):
        why.append('J not finite')
    if not check_limits(p, Limits(limits['max_climb_deg'], limits['max_dive_deg'],
                                  limits['min_turn_radius_m'])):
        why.append('breaks the limits')
    return {'J': j, 'feasible': not why, 'why': ', '.join(why)}
