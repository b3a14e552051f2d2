"""Run a bench suite: ``python -m bench SUITE [options]`` from the repository root.

``python -m bench`` (or ``--list``) lists the suites, ``python -m bench SUITE --help``
shows a suite's options. A suite is a function ``main(argv) -> int`` (None counts as 0);
adding one is a line in :data:`SUITES`.
"""

from __future__ import annotations

import importlib
import sys

#: Suite -> (module, function, one-line help).
SUITES: dict[str, tuple[str, str, str]] = {
    'airspace': ('bench.suites.airspace', 'main',
                 'zones and terrain: ours beside a blocked-edge grid yardstick and RRT*'),
    'blas_threads': ('bench.suites.blas_threads', 'main',
                     'plans with BLAS held to one thread and without, in turns'),
    'batch': ('bench.batch', 'main',
              'threat-planner batch at scale: backends, kill and resume, robust plans'),
    'before_after': ('bench.suites.before_after', 'main',
                     'cold plans of two checkouts, case by case, taking turns'),
    'benchmark': ('bench.suites.benchmark', 'main',
                  'J and time in the box against the yardsticks, OMPL and a grid floor'),
    'cli_scale': ('bench.suites.cli_scale', 'main',
                  'threat-planner plan on 10,000 threats against a bare Delaunay'),
    'cold_start': ('bench.suites.cold_start', 'main',
                   'first plan after an install and in a new process: CLI, plan(), node'),
    'crowded_fields': ('bench.suites.crowded_fields', 'main',
                       'best on fresh crowded (or random) fields against the in-box yardstick'),
    'detection': ('bench.suites.detection', 'main',
                  'issue 43: detection plans against paper plans and an SLSQP yardstick'),
    'dds_discovery': ('bench.suites.dds_discovery', 'main',
                      "planner_node's first path with its discovery profile and without"),
    'faults': ('bench.suites.faults', 'main',
               'kill -9 the node while it plans and records, SIGINT a long plan'),
    'flood': ('bench.suites.flood', 'main',
              'flood the node with threat updates: coalesced, responsive, no backlog'),
    'omp_wait': ('bench.suites.omp_wait', 'main',
                 'the parallel kernels\' OpenMP wait policy, quiet and beside busy loops'),
    'large_fields': ('bench.suites.large_fields', 'main',
                     'issue 42 speed: 10,000 and 100,000 fresh threats, 20 threats, ratios'),
    'flights': ('bench.suites.flights', 'main',
                'fresh simulated flights: pop-ups, moving threats, latency, J against hindsight'),
    'fresh': ('bench.suites.fresh', 'main',
              'new random fields every run: HEAD beside a baseline tag and the yardsticks'),
    'getplan_latency': ('bench.suites.getplan_latency', 'main',
                        'GetPlan round trips of a node in another process, topic replans'),
    'inbox_quality': ('bench.suites.inbox_quality', 'main',
                      'best with the angle limits off against reference_box.json'),
    'make_airspace_scenarios': ('bench.suites.make_airspace_scenarios', 'main',
                                'write the six airspace scenarios into test/data/'),
    'node_latency': ('bench.suites.node_latency', 'main',
                     'publish a threat picture, receive path: the node end to end'),
    'node_start': ('bench.suites.node_start', 'main',
                   'planner_node of two checkouts started in turns: seconds to its first path'),
    'numba_newest': ('bench.suites.numba_newest', 'main',
                     'the bundled 20-threat cases with the newest numba beside the pinned one'),
    'paper_methods': ('bench.suites.paper_methods', 'main',
                      'paper and improved at 20 threats, beside a base checkout'),
    'perturbation': ('bench.suites.perturbation', 'main',
                     'how far J moves when every threat moves by a nanometre'),
    'profile_kernel': ('bench.suites.profile_kernel', 'main',
                       'one J-and-gradient evaluation at 40 segments x 20 threats'),
    'profile_plan': ('bench.suites.profile_plan', 'main',
                     'cProfile of plan (best) on the bundled 20-threat scenarios'),
    'random_fields': ('bench.suites.random_fields', 'main',
                      'cold plans of two checkouts on 45 random fields'),
    'record_regression_bags': ('bench.suites.record_regression_bags', 'main',
                               're-record (or --check) the regression bags of test/data/bags'),
    'recording_overhead': ('bench.suites.recording_overhead', 'main',
                           'node latency with and without MCAP recording, bytes per plan'),
    'responsiveness': ('bench.suites.responsiveness', 'main',
                       'parameter gets during a long plan, and exit on SIGTERM'),
    'scale': ('bench.suites.scale', 'main',
              'stage times and memory of best from 20 to 10,000 threats'),
    'soak': ('bench.suites.soak', 'main',
             'drifting threats at 10 Hz for minutes with recording on'),
    'speed': ('bench.suites.speed', 'main',
              'speed and quality of best with the flight limits on and off'),
    'yardstick': ('bench.suites.yardstick', 'main',
                  'compute the in-box and limited yardsticks (yardstick.json)'),
}


def listing() -> str:
    """Return the usage line and one line a suite with its help."""
    width = max(map(len, SUITES))
    return '\n'.join(['usage: python -m bench SUITE [options]  (SUITE --help for its own)',
                      '', 'suites:']
                     + [f'  {name:{width}s}  {help_}' for name, (_, _, help_) in SUITES.items()])


def main(argv: list[str] | None = None) -> int:
    """Run the suite named first in `argv` with the rest; return its exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv or argv[0] in ('--list', '-l', '--help', '-h'):
        print(listing())
        return 0
    name, rest = argv[0], argv[1:]
    if name not in SUITES:
        print(f'python -m bench: no suite {name!r} (python -m bench --list names them)',
              file=sys.stderr)
        return 2
    module, function, _ = SUITES[name]
    # argparse names the program after sys.argv[0]: usage lines then show this command.
    sys.argv = [f'python -m bench {name}', *rest]
    status = getattr(importlib.import_module(module), function)(rest)
    return 0 if status is None else int(status)


if __name__ == '__main__':
    sys.exit(main())
