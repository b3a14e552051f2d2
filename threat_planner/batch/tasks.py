"""A study's tasks: one plan each, with a stable key and seeds derived from it.

A task is one plan of one (scenario, w, method, settings) combination, nominal or robust;
its rows are the plan's own and, with uncertainty, one per evaluation picture. The key is
a hash of everything that decides those rows (the scenario file's bytes included), so a
resumed run, another backend or another machine finds the same tasks under the same keys.
The pictures are seeded by the study's seed and the key's scenario part: every plan of a
scenario is scored on the same evaluation pictures (nominal and robust plans, every w),
and every robust plan of it averages over the same pictures, drawn apart from those.
"""

from __future__ import annotations

from dataclasses import dataclass
import hashlib
import itertools
import json

from threat_planner.batch.study import Sampling, Study
from threat_planner.core.inputs.config import PlannerConfig

__all__ = ['Task', 'chunks', 'task_list']

#: Most work units (about one 20-threat plan each) grouped into one chunk: a chunk's
#: overhead (a round trip to a worker, one part file) is then a small share of its work,
#: and a killed run loses at most the chunks in flight.
CHUNK_UNITS = 16
#: Chunks per worker at least, so that the workers finish together.
CHUNKS_PER_WORKER = 4


@dataclass(frozen=True)
class Task:
    """One plan of a study.

    Attributes
    ----------
    index : int
        Position in the study's task list (the order of the table's rows).
    key : str
        Stable identity (hex).
    scenario : str
        The scenario's key (path relative to the study file).
    path : str
        The scenario file.
    w : float
        Threat weight.
    method : str
        Planning method.
    settings : tuple of (str, object)
        The swept settings' values.
    plan : str
        'nominal' or 'robust'.
    sampling : Sampling or None
        The study's uncertainty, None without.
    threats : int
        Threats of the scenario.

    """

    index: int
    key: str
    scenario: str
    path: str
    w: float
    method: str
    settings: tuple[tuple[str, object], ...]
    plan: str
    sampling: Sampling | None
    threats: int

    @property
    def config(self) -> PlannerConfig:
        """The plan's settings."""
        return PlannerConfig(w=self.w, method=self.method, **dict(self.settings)).validated()

    @property
    def evaluation_seed(self) -> list[int]:
        """Seed words of the evaluation pictures."""
        return _seed('evaluation', self.scenario, self.sampling)

    @property
    def robust_seed(self) -> list[int]:
        """Seed words of the pictures a robust plan averages over."""
        return _seed('robust', self.scenario, self.sampling)

    @property
    def units(self) -> float:
        """Rough work, in 20-threat plans: the planned field's size and the scoring."""
        s = self.sampling
        field = self.threats * (s.robust_samples if self.plan == 'robust' else 1)
        scoring = 0 if s is None else s.samples * self.threats / 2000.0
        return 0.8 + field / 100.0 + scoring


def _seed(label: str, scenario: str, sampling: Sampling | None) -> list[int]:
    digest = hashlib.sha256(f'{label}\0{scenario}'.encode()).digest()
    base = 0 if sampling is None else sampling.seed
    return [base, int.from_bytes(digest[:4], 'little'), int.from_bytes(digest[4:8], 'little')]


def task_list(study: Study) -> list[Task]:
    """Every task of the study: scenario, then w, method, each setting, plan, outermost first."""
    names = [name for name, _ in study.settings]
    s = study.sampling
    uncertainty = None if s is None else {
        'samples': s.samples, 'position_sigma_m': s.position_sigma_m,
        'intensity_sigma': s.intensity_sigma, 'seed': s.seed}
    out = []
    for sc in study.scenarios:
        for w, method, *values in itertools.product(study.w, study.methods,
                                                    *(v for _, v in study.settings)):
            settings = tuple(zip(names, values))
            for plan in study.plans:
                ident = {'scenario': sc.key, 'digest': sc.digest, 'w': w, 'method': method,
                         'settings': dict(settings), 'plan': plan, 'uncertainty': uncertainty,
                         'robust': s.robust_samples if plan == 'robust' else None}
                key = hashlib.sha256(json.dumps(ident, sort_keys=True).encode()).hexdigest()
                out.append(Task(len(out), key[:20], sc.key, sc.path, w, method, settings,
                                plan, s, sc.threats))
    return out


def chunks(tasks: list[Task], workers: int) -> list[list[Task]]:
    """Group tasks, in order, into chunks of at most CHUNK_UNITS units of work.

    With few tasks the chunks get smaller, down to one task, so that every worker has
    CHUNKS_PER_WORKER of them.
    """
    if not tasks:
        return []
    total = sum(t.units for t in tasks)
    budget = min(CHUNK_UNITS, total / (CHUNKS_PER_WORKER * max(workers, 1)))
    out: list[list[Task]] = []
    current: list[Task] = []
    load = 0.0
    for t in tasks:
        if current and load + t.units > budget:
            out.append(current)
            current, load = [], 0.0
        current.append(t)
        load += t.units
    out.append(current)
    return out
