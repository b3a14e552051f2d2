"""``threat-planner batch`` and the robust options of ``plan``.

``batch`` loads pyarrow (and Ray) only when it runs, so ``plan`` pays for neither.
"""

from __future__ import annotations

import argparse
import math
import os

from threat_planner.cli.options import ProgressBar
from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.inputs.scenario import Scenario
from threat_planner.core.result import PlanResult
from threat_planner.errors import InputError

__all__ = ['add_batch_command', 'add_robust_options', 'robust_plan', 'robust_summary']


def add_batch_command(sub: argparse._SubParsersAction) -> None:
    """Add the ``batch`` verb."""
    p = sub.add_parser(
        'batch', help='run a study: sweep scenarios, w, methods and settings in parallel',
        description='Run every plan of a study file on worker processes (or a Ray '
                    'cluster), committing rows to OUT/results.parquet as they finish; the '
                    'same command again runs only what is missing. Writes OUT/report.md.')
    p.add_argument('study', help='study YAML file (scenarios, w, method, settings, '
                                 'uncertainty, robust)')
    p.add_argument('--out', required=True, help='results folder')
    p.add_argument('--workers', type=int, default=None,
                   help=f'worker processes (default: the usable CPUs, {_cpus()} here); '
                        'with --ray auto, the CPUs of the local cluster it starts')
    p.add_argument('--ray', metavar='ADDRESS|auto', default=None,
                   help="run as Ray tasks on the cluster at ADDRESS; 'auto' = RAY_ADDRESS "
                        "or a local cluster started for the run (pip install "
                        "'threat_planner[cluster]')")
    p.set_defaults(func=_cmd_batch)


def _cpus() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def _cmd_batch(args: argparse.Namespace) -> int:
    from threat_planner.batch.runner import run_batch
    bar = ProgressBar('batch')
    try:
        run = run_batch(args.study, args.out, workers=args.workers, ray=args.ray,
                        progress=bar)
    finally:
        bar.close()
    before = run.tasks - run.ran
    print(f'{args.study}: {run.tasks} tasks, {run.ran} run now'
          + (f' ({before} done before)' if before else '')
          + f' on {run.backend} in {run.seconds:.1f} s; {run.rows} rows'
          + (f', {run.errors} plans refused (see the report)' if run.errors else ''))
    print(f'  results: {run.results}')
    print(f'  report:  {run.report}')
    return 0


def add_robust_options(parser: argparse.ArgumentParser) -> None:
    """Add ``--robust K --position-sigma M --intensity-sigma S --robust-seed N``."""
    g = parser.add_argument_group(
        'robust', 'plan for the least mean J over K pictures of the threats moved by '
                  'N(0, M) per axis and their intensities scaled by lognormal(0, S)')
    g.add_argument('--robust', type=int, metavar='K', default=None,
                   help='pictures to average over (a plan on K times the threats)')
    g.add_argument('--position-sigma', type=float, metavar='M', default=0.0,
                   help='spread of each threat coordinate [m] (default 0)')
    g.add_argument('--intensity-sigma', type=float, metavar='S', default=0.0,
                   help='sigma of the lognormal factor on each intensity (default 0)')
    g.add_argument('--robust-seed', type=int, metavar='N', default=0,
                   help='seed of the pictures (default 0)')


def robust_plan(scenario: Scenario, cfg: PlannerConfig, args: argparse.Namespace,
                progress=None) -> PlanResult:
    """Plan ``scenario`` robustly as the options say (InputError names a bad option)."""
    from threat_planner.core.robust import plan_robust, Uncertainty
    if args.robust < 1:
        raise InputError(f'--robust: must be an integer >= 1, got {args.robust}')
    for flag, v in (('--position-sigma', args.position_sigma),
                    ('--intensity-sigma', args.intensity_sigma)):
        if not math.isfinite(v) or v < 0:
            raise InputError(f'{flag}: must be a finite number >= 0, got {v:g}')
    if args.robust_seed < 0:
        raise InputError(f'--robust-seed: must be an integer >= 0, got {args.robust_seed}')
    if getattr(args, 'record', None):
        raise InputError('--robust: a robust plan cannot be recorded (--record)')
    return plan_robust(scenario.threats, scenario.start, scenario.goal, scenario.box, cfg,
                       args.robust, Uncertainty(args.position_sigma, args.intensity_sigma),
                       args.robust_seed, airspace=scenario.airspace or None,
                       progress=progress)


def robust_summary(scenario: Scenario, result: PlanResult, args: argparse.Namespace
                   ) -> tuple[str, dict]:
    """Return the line ``plan --robust`` prints and the ``robust`` entry of its JSON."""
    from threat_planner.core.robust import picture_costs
    nominal = picture_costs(result.path, [scenario.threats], result.w,
                            scenario.airspace or None)[0]
    line = (f'  robust:  the final J is the mean over {args.robust} pictures (position '
            f'sigma {args.position_sigma:g} m, intensity sigma {args.intensity_sigma:g}, '
            f'seed {args.robust_seed}); on the nominal picture J={nominal.J:.3f} '
            f'J_L={nominal.J_L:.3f} J_R={nominal.J_R:.3f}')
    return line, {'samples': args.robust, 'position_sigma_m': args.position_sigma,
                  'intensity_sigma': args.intensity_sigma, 'seed': args.robust_seed,
                  'nominal_cost': nominal.as_dict()}
