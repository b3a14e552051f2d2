"""The radar cross-section setting ``rcs``: its text form and its scenario mapping.

One setting holds the target's RCS model (issue 43), the same text on the command line and
in the node's parameters: ``'constant S'`` (sigma = S [m^2] from every aspect) or
``'ellipsoid A B C'`` (semi-axes [m] along the nose, the right wing and down). A scenario's
``detection: rcs:`` gives it as a mapping, ``{constant: S}`` or ``{ellipsoid: [A, B, C]}``.
"""

from __future__ import annotations

import math
import numbers

from threat_planner.errors import InputError

__all__ = ['RCS_KINDS', 'parse_rcs', 'rcs_text']

#: The RCS models and the number of values each takes.
RCS_KINDS = {'constant': 1, 'ellipsoid': 3}
#: Largest RCS value accepted: a semi-axis [m] or a constant [m^2].
RCS_MAX = 1.0e6


def parse_rcs(value: object, field: str = 'rcs') -> tuple[str, tuple[float, ...]]:
    """Return ``(kind, values)`` of an RCS given as text or as a one-key mapping.

    Parameters
    ----------
    value : str or dict
        ``'constant 1.0'``, ``'ellipsoid 3 1 0.5'`` (commas allowed), ``{constant: 1.0}``
        or ``{ellipsoid: [3, 1, 0.5]}``.
    field : str
        Name of the field in error messages.

    Returns
    -------
    tuple
        ``('constant', (S,))`` [m^2] or ``('ellipsoid', (A, B, C))`` [m].

    Raises
    ------
    InputError
        Naming `field` and the bad value, for an unknown kind, a wrong count, or a value
        that is not finite and > 0.

    """
    if isinstance(value, dict):
        if len(value) != 1:
            raise InputError(f'{field}: must be one of {{constant: S}} or {{ellipsoid: '
                             f'[A, B, C]}}, got {len(value)} keys {sorted(map(str, value))}')
        kind, raw = next(iter(value.items()))
        numbers_ = list(raw) if isinstance(raw, (list, tuple)) else [raw]
    elif isinstance(value, str):
        words = value.replace(',', ' ').split()
        if not words:
            raise InputError(f"{field}: must be 'constant S' or 'ellipsoid A B C', got ''")
        kind, numbers_ = words[0], words[1:]
    else:
        raise InputError(f"{field}: must be 'constant S' or 'ellipsoid A B C', got {value!r}")
    if kind not in RCS_KINDS:
        raise InputError(f'{field}: kind must be one of {", ".join(RCS_KINDS)}, got {kind!r}')
    count = RCS_KINDS[kind]
    if len(numbers_) != count:
        raise InputError(f'{field}: {kind} takes {count} value{"s" * (count > 1)}, '
                         f'got {len(numbers_)}')
    values = []
    for raw in numbers_:
        number = _number(raw)
        if number is None or not (0.0 < number <= RCS_MAX):
            unit = 'm^2' if kind == 'constant' else 'm'
            raise InputError(f'{field}: {kind} values must be finite, > 0 and <= '
                             f'{RCS_MAX:g} [{unit}], got {raw!r}')
        values.append(number)
    return kind, tuple(values)


def rcs_text(kind: str, values: tuple[float, ...]) -> str:
    """Return the setting's text of an RCS model (inverse of :func:`parse_rcs`)."""
    return ' '.join([kind, *(repr(float(v)) for v in values)])


def _number(raw: object) -> float | None:
    if isinstance(raw, bool):
        return None
    if isinstance(raw, str):
        try:
            raw = float(raw)
        except ValueError:
            return None
    if not isinstance(raw, numbers.Real):
        return None
    number = float(raw)
    return number if math.isfinite(number) else None
