"""Command-line options shared by the verbs, derived from the settings' declarations."""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path
import sys
from typing import Optional

from threat_planner.core.inputs.config import PlannerConfig
from threat_planner.core.inputs.scenario_detection import DETECTION_SETTINGS
from threat_planner.core.inputs.settings import PLANNER_SETTINGS, Setting

__all__ = ['ProgressBar', 'add_planner_options', 'config_from', 'output_file', 'overrides']

#: Options whose flag inverts the setting (``--leave-box`` sets confine_to_box false).
_INVERTED = {'confine_to_box': 'let the optimised path leave the bounds box'}
#: Settings a scenario file may give (key ``speed`` and the ``detection`` block), which then
#: stand in for the default: the scenario's key of each.
SCENARIO_KEYS = {'speed_mps': 'speed',
                 **{name: f'detection.{key}' for key, name in DETECTION_SETTINGS.items()}}


def _cli_settings() -> list[Setting]:
    return [s for s in PLANNER_SETTINGS.values() if s.cli is not None]


def add_planner_options(parser: argparse.ArgumentParser, *, recorded: bool = False) -> None:
    """Add one option per planner setting that has a command-line name.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The verb's parser.
    recorded : bool
        The options override recorded values (``replay``): no defaults, help says so.

    """
    for s in _cli_settings():
        flag = f'--{s.cli}'
        if s.kind is bool:
            helptext = _INVERTED.get(s.name, s.doc)
            parser.add_argument(flag, dest=s.name, action='store_const',
                                const=s.name not in _INVERTED, default=None, help=helptext)
            continue
        key = SCENARIO_KEYS.get(s.name)
        default = '' if recorded else (
            (f"; if not given, the scenario's {key}" if key else '') + f' (default: {s.default})')
        instead = ' instead of the recorded one' if recorded else ''
        kwargs = {'choices': s.choices} if s.choices else {'type': s.kind}
        metavar = None if s.choices else s.cli.upper().replace('-', '_')
        parser.add_argument(flag, dest=s.name, default=None, metavar=metavar,
                            help=f'{s.doc}{instead}{default}', **kwargs)


def overrides(args: argparse.Namespace) -> dict[str, object]:
    """Return the PlannerConfig fields set on the command line."""
    return {s.name: getattr(args, s.name) for s in _cli_settings()
            if getattr(args, s.name, None) is not None}


def config_from(args: argparse.Namespace, scenario: Optional[object] = None) -> PlannerConfig:
    """Return the PlannerConfig of the command line's settings, validated.

    A scenario's own ``speed`` [m/s] and ``detection`` block (cost, max_detection,
    scan_period, p_fa, swerling, rcs) stand in for the defaults; the options (``--speed``,
    ``--cost``, ...) override them.
    """
    base = PlannerConfig()
    speed = getattr(scenario, 'speed', None)
    if speed is not None:
        base = replace(base, speed_mps=speed)
    base = replace(base, **getattr(scenario, 'detection', {}))
    return replace(base, **overrides(args)).validated()


class ProgressBar:
    """A progress(done, total) callback drawing a tqdm bar on stderr once work is long.

    The bar appears only for sweeps that run for more than a second.
    """

    def __init__(self, desc: str, total: Optional[int] = None) -> None:
        self._desc = desc
        self._bar = None
        if total is not None:
            self._open(total)

    def _open(self, total: int) -> None:
        from tqdm import tqdm
        self._bar = tqdm(total=total, desc=self._desc, delay=1.0, leave=False,
                         file=sys.stderr)

    def __call__(self, done: int, total: int) -> None:
        """Move the bar to `done` of `total`."""
        if self._bar is None:
            self._open(total)
        self._bar.update(done - self._bar.n)

    def tick(self, label: str) -> None:
        """Advance one step, showing `label`."""
        self._bar.set_postfix_str(label)
        self._bar.update(1)

    def close(self) -> None:
        """Remove the bar, if it was drawn."""
        if self._bar is not None:
            self._bar.close()


def output_file(name: str | Path) -> Path:
    """Return an output file's path with its folder created, as ``--plot`` always had it."""
    path = Path(name)
    path.parent.mkdir(parents=True, exist_ok=True)
    return path
