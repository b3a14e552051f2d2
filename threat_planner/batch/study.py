"""Study files: which scenarios, weights, methods and settings to sweep, checked up front.

Layout::

    scenarios: [fields/*.yaml, other.yaml]   # globs, relative to the study file
    w: [0.2, 0.5, 0.8]                        # a value or a list
    method: [best, paper]                     # a value or a list
    settings: {max_climb_deg: [20, 30]}       # any plan setting, a value or a list
    uncertainty: {samples: 32, position_sigma_m: 5.0, intensity_sigma: 0.2, seed: 1}
    robust: {samples: 16}                     # needs uncertainty

The sweep is the product of w, method and every setting, for each scenario. Every problem
is found before any plan runs and reported as one line naming the field
(:class:`~threat_planner.errors.InputError`).
"""

from __future__ import annotations

from dataclasses import dataclass
import difflib
import glob
import hashlib
import os
from pathlib import Path

import yaml

from threat_planner.core.inputs.scenario import load_scenario
from threat_planner.core.inputs.settings import PLANNER_SETTINGS
from threat_planner.errors import InputError

__all__ = ['Sampling', 'Study', 'StudyScenario', 'load_study', 'study_from_dict']

TOP_KEYS = ('scenarios', 'w', 'method', 'settings', 'uncertainty', 'robust')
UNCERTAINTY_KEYS = ('samples', 'position_sigma_m', 'intensity_sigma', 'seed')
ROBUST_KEYS = ('samples',)
#: Defaults of the optional blocks' keys.
UNCERTAINTY_DEFAULTS = {'samples': 32, 'position_sigma_m': 0.0, 'intensity_sigma': 0.0,
                        'seed': 0}
ROBUST_DEFAULTS = {'samples': 16}
#: Planner settings with a top-level key of their own.
OWN_KEYS = ('w', 'method')


@dataclass(frozen=True)
class StudyScenario:
    """One scenario of a study.

    Attributes
    ----------
    key : str
        Its path relative to the study file's folder (posix), the table's ``scenario``.
    path : str
        Absolute path of the file.
    digest : str
        SHA-256 of the file's bytes (a changed file makes new tasks).
    threats : int
        Number of threats (to size the work).

    """

    key: str
    path: str
    digest: str
    threats: int


@dataclass(frozen=True)
class Sampling:
    """The ``uncertainty`` and ``robust`` blocks.

    Attributes
    ----------
    samples : int
        Evaluation pictures each plan is scored on.
    position_sigma_m : float
        Spread of each threat coordinate [m].
    intensity_sigma : float
        Sigma of the lognormal factor on each intensity.
    seed : int
        Seed of every picture of the study.
    robust_samples : int
        Pictures a robust plan averages over; 0 = no robust plans.

    """

    samples: int
    position_sigma_m: float
    intensity_sigma: float
    seed: int
    robust_samples: int = 0


@dataclass(frozen=True)
class Study:
    """A checked study.

    Attributes
    ----------
    path : Path
        The study file (absolute).
    scenarios : tuple of StudyScenario
        In the order the globs found them (each glob's matches sorted), no repeats.
    w : tuple of float
        The weights swept.
    methods : tuple of str
        The methods swept.
    settings : tuple of (str, tuple)
        Each swept setting and its values, in the file's order.
    sampling : Sampling or None
        The uncertainty (and robust) blocks, None without uncertainty.

    """

    path: Path
    scenarios: tuple[StudyScenario, ...]
    w: tuple[float, ...]
    methods: tuple[str, ...]
    settings: tuple[tuple[str, tuple], ...]
    sampling: Sampling | None = None

    @property
    def plans(self) -> tuple[str, ...]:
        """The plans made of each combination: nominal, and robust if asked for."""
        robust = self.sampling is not None and self.sampling.robust_samples > 0
        return ('nominal', 'robust') if robust else ('nominal',)

    def fingerprint(self) -> dict:
        """Everything that decides the study's rows, JSON-ready (kept beside the results)."""
        return {
            'scenarios': [[s.key, s.digest] for s in self.scenarios],
            'w': list(self.w), 'method': list(self.methods),
            'settings': {name: list(values) for name, values in self.settings},
            'uncertainty': None if self.sampling is None else {
                k: getattr(self.sampling, k) for k in UNCERTAINTY_KEYS},
            'robust': None if not self.sampling or not self.sampling.robust_samples
            else {'samples': self.sampling.robust_samples},
        }


def load_study(path: str | Path) -> Study:
    """Read and check a study file; every scenario it names is loaded and checked too.

    Raises
    ------
    InputError
        One line: the file, the field and what is wrong with it.

    """
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f'{path}: cannot read ({getattr(exc, "strerror", None) or exc})'
                         ) from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f' at line {mark.line + 1}' if mark else ''
        raise InputError(f'{path}: not valid YAML{where}') from None
    return study_from_dict(data, path)


def study_from_dict(data: object, path: str | Path) -> Study:
    """Check a study's mapping; ``path`` is the study file (globs are relative to it)."""
    path = Path(path).resolve()

    def fail(message: str) -> InputError:
        return InputError(f'{path}: {message}')

    if not isinstance(data, dict):
        raise fail(f'must be a mapping with the keys {", ".join(TOP_KEYS)}')
    _check_keys(data, TOP_KEYS, '', fail)
    if 'scenarios' not in data:
        raise fail('scenarios: missing (a glob or a list of globs of scenario files)')
    scenarios = _scenarios(data['scenarios'], path.parent, fail)
    w = tuple(float(v) for v in _sweep(data, 'w', fail))
    methods = tuple(_sweep(data, 'method', fail))
    settings = data.get('settings', {})
    if settings is None or not isinstance(settings, dict):
        raise fail(f'settings: must be a mapping of plan settings, got {settings!r}')
    swept = []
    for name in settings:
        if name in OWN_KEYS:
            raise fail(f'settings.{name}: sweep {name} with the top-level key "{name}"')
        if name not in PLANNER_SETTINGS:
            close = difflib.get_close_matches(str(name), list(PLANNER_SETTINGS), n=1)
            hint = f'; did you mean "{close[0]}"?' if close else ''
            raise fail(f'settings.{name}: not a plan setting{hint}')
        swept.append((name, tuple(_sweep(settings, name, fail, 'settings.'))))
    sampling = _sampling(data, fail)
    return Study(path, scenarios, w, methods, tuple(swept), sampling)


def _check_keys(mapping: dict, known: tuple, where: str, fail) -> None:
    for key in mapping:
        if key not in known:
            close = difflib.get_close_matches(str(key), known, n=1, cutoff=0.6)
            hint = f'; did you mean "{close[0]}"?' if close else ''
            raise fail(f'unknown field "{where}{key}"{hint} (known: {", ".join(known)})')


def _scenarios(value: object, base: Path, fail) -> tuple[StudyScenario, ...]:
    patterns = [value] if isinstance(value, str) else value
    if not isinstance(patterns, list) or not all(isinstance(p, str) for p in patterns):
        raise fail(f'scenarios: must be a glob or a list of globs, got {value!r}')
    if not patterns:
        raise fail('scenarios: empty list (give at least one glob)')
    found: dict[str, StudyScenario] = {}
    for i, pattern in enumerate(patterns):
        where = 'scenarios' if isinstance(value, str) else f'scenarios[{i}]'
        if not pattern.strip():
            raise fail(f'{where}: empty glob')
        full = pattern if os.path.isabs(pattern) else str(base / pattern)
        matches = sorted(p for p in glob.glob(full, recursive=True) if os.path.isfile(p))
        if not matches:
            raise fail(f'{where}: "{pattern}" matches no file (relative to {base})')
        for m in matches:
            real = os.path.realpath(m)
            if real in found:
                continue
            scenario = load_scenario(real)   # a bad file: its own one-line ScenarioError
            key = Path(os.path.relpath(real, base)).as_posix()
            digest = hashlib.sha256(Path(real).read_bytes()).hexdigest()
            found[real] = StudyScenario(key, real, digest, len(scenario.threats))
    return tuple(found.values())


def _sweep(mapping: dict, name: str, fail, prefix: str = '') -> list:
    """Return the checked values of one swept setting (its default alone if absent)."""
    setting = PLANNER_SETTINGS[name]
    if name not in mapping:
        return [setting.default]
    raw = mapping[name]
    values = raw if isinstance(raw, list) else [raw]
    if not values:
        raise fail(f'{prefix}{name}: empty sweep (give a value or a non-empty list)')
    out = []
    for i, v in enumerate(values):
        where = f'{prefix}{name}' + (f'[{i}]' if isinstance(raw, list) else '')
        try:
            setting.check(v)
        except InputError:
            raise fail(f'{where}: {setting.rule}, got {v!r}') from None
        v = setting.kind(v) if setting.kind in (float, int) else v
        if v in out:
            raise fail(f'{where}: {v!r} is in the sweep twice')
        out.append(v)
    return out


def _sampling(data: dict, fail) -> Sampling | None:
    unc, rob = data.get('uncertainty'), data.get('robust')
    if rob is not None and unc is None:
        raise fail('robust: needs an uncertainty block (the spread of the pictures)')
    if unc is None:
        return None
    block = _block(unc, 'uncertainty', UNCERTAINTY_KEYS, UNCERTAINTY_DEFAULTS, fail)
    robust = 0
    if rob is not None:
        robust = _block(rob, 'robust', ROBUST_KEYS, ROBUST_DEFAULTS, fail)['samples']
    return Sampling(int(block['samples']), float(block['position_sigma_m']),
                    float(block['intensity_sigma']), int(block['seed']), int(robust))


def _block(value: object, name: str, keys: tuple, defaults: dict, fail) -> dict:
    if not isinstance(value, dict):
        raise fail(f'{name}: must be a mapping with the keys {", ".join(keys)}, got {value!r}')
    _check_keys(value, keys, f'{name}.', fail)
    out = {**defaults, **value}
    for key, v in out.items():
        integer = key in ('samples', 'seed')
        ok = not isinstance(v, bool) and isinstance(v, (int, float)) and v == v \
            and abs(v) != float('inf')
        if integer:
            ok = ok and v == int(v) and v >= (1 if key == 'samples' else 0)
            rule = 'an integer >= 1' if key == 'samples' else 'an integer >= 0'
        else:
            ok = ok and v >= 0
            rule = 'a finite number >= 0'
        if not ok:
            raise fail(f'{name}.{key}: must be {rule}, got {v!r}')
    return out
