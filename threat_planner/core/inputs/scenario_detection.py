"""A scenario's ``detection`` block (issue 43) and the checks a scenario's keys share.

The block's keys, the settings they give, and their checks with errors naming the key as
the file wrote it; :mod:`threat_planner.core.inputs.scenario` documents the layout.
"""

from __future__ import annotations

import difflib
from typing import Optional

from threat_planner.core.inputs.rcs import parse_rcs, rcs_text
from threat_planner.core.inputs.settings import PLANNER_SETTINGS
from threat_planner.errors import InputError

__all__ = ['BLOCK_ONLY', 'DETECTION_KEYS', 'DETECTION_SETTINGS', 'check_keys', 'detection_of',
           'file_block', 'setting_value', 'speed_of']

#: Keys of the ``detection`` block and the PlannerConfig field each sets, in the order a
#: saved file writes them; ``speed`` is the top-level ``speed`` (Scenario.speed).
DETECTION_SETTINGS = {'cost': 'cost_model', 'max_detection': 'max_detection',
                      'scan_period': 'scan_period_s', 'p_fa': 'p_fa', 'swerling': 'swerling',
                      'rcs': 'rcs'}
DETECTION_KEYS = ('cost', 'max_detection', 'speed', 'scan_period', 'p_fa', 'swerling', 'rcs')
#: Keys a user may put at the top level that belong in the ``detection`` block.
BLOCK_ONLY = ('cost', 'max_detection', 'scan_period', 'p_fa', 'swerling', 'rcs')


def check_keys(mapping: dict, known: tuple, where: str, fail) -> None:
    """Refuse an unknown (often misspelt) key, naming it and the nearest known one."""
    for key in mapping:
        if key in known:
            continue
        close = difflib.get_close_matches(str(key), known, n=1, cutoff=0.6)
        hint = f'; did you mean "{close[0]}"?' if close else ''
        # A key with control characters (a stray newline) is shown escaped: one line.
        name = str(key) if str(key).isprintable() else repr(str(key))[1:-1]
        raise fail(f'unknown field "{where}{name}"{hint} (known: {", ".join(known)})')


def setting_value(name: str, value: object, key: str) -> object:
    """Return `value` checked as setting `name`, an error naming the file's `key`."""
    setting = PLANNER_SETTINGS[name]
    try:
        setting.check(value)
    except InputError as exc:
        # The file's key, not the setting's: the user wrote 'speed', 'detection.p_fa'.
        rule, got = str(exc).split(': ', 1)[1].rsplit(', got ', 1)
        unit = f' [{setting.unit}]' if setting.unit else ''
        raise InputError(f'{key}: {rule}{unit}, got {got}') from None
    return setting.kind(value)


def speed_of(data: dict) -> Optional[float]:
    """Return the file's cruise speed [m/s], checked as ``speed_mps``; None if absent.

    It is the top-level ``speed`` or ``detection.speed``; both may be given only alike.
    """
    top = setting_value('speed_mps', data['speed'], 'speed') if 'speed' in data else None
    block = data.get('detection')
    if not isinstance(block, dict) or 'speed' not in block:
        return top
    inner = setting_value('speed_mps', block['speed'], 'detection.speed')
    if top is not None and top != inner:
        raise InputError(f'speed: {top:g} and detection.speed: {inner:g} differ; they are '
                         'one setting (speed_mps): give one, or both alike')
    return inner


def detection_of(data: dict) -> dict:
    """Return the ``detection`` block's settings by PlannerConfig field, checked."""
    block = data.get('detection')
    if block is None:
        return {}
    if not isinstance(block, dict):
        raise InputError(f'detection: must be a mapping of {", ".join(DETECTION_KEYS)}, '
                         f'got {block!r}')
    check_keys(block, DETECTION_KEYS, 'detection.', InputError)
    out = {}
    for key, name in DETECTION_SETTINGS.items():
        if key not in block:
            continue
        if name == 'rcs':
            out[name] = rcs_text(*parse_rcs(block[key], 'detection.rcs'))
        else:
            out[name] = setting_value(name, block[key], f'detection.{key}')
    return out


def file_value(name: str, value: object) -> object:
    """Return a detection setting as a scenario file writes it (``rcs`` as its mapping)."""
    if name == 'rcs':
        kind, values = parse_rcs(value)
        return {kind: values[0] if kind == 'constant' else list(values)}
    return value


def file_block(detection: dict) -> dict:
    """Return a Scenario's detection settings as the file's ``detection`` block."""
    return {key: file_value(name, detection[name]) for key, name in DETECTION_SETTINGS.items()
            if name in detection}
