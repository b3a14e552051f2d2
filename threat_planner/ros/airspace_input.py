"""The node's airspace inputs: parameter ``airspace_file`` and the start/goal checks.

Parts and which wins: the zones and the terrain are two parts, and for each the latest
input wins. Parameter ``airspace_file`` (loaded at start-up and whenever it is set) sets
both parts to the file's (a file without ``terrain`` removes the terrain; '' removes
both); a ``no_fly_zones`` message replaces the zones, the file's included; a ``terrain``
message replaces the terrain (an empty image removes it). The ``terrain_*`` parameters
describe the grid of the ``terrain`` topic only; a file's terrain carries its own.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional, Sequence

from numpy.typing import NDArray
import yaml

from threat_planner.core.world.airspace import Airspace
from threat_planner.core.world.terrain import Terrain
from threat_planner.core.world.zones import Zone
from threat_planner.errors import InputError

__all__ = ['AIRSPACE_FILE_KEYS', 'airspace_of', 'check_airspace_endpoints',
           'load_airspace_file']

#: Keys an airspace file may hold (the scenario's airspace keys).
AIRSPACE_FILE_KEYS = ('no_fly_zones', 'terrain')


def load_airspace_file(path: str) -> Airspace:
    """Load and validate an airspace YAML file; '' gives an empty airspace.

    Raises
    ------
    InputError
        One line naming the file and the bad field (unknown key, negative radius,
        non-simple polygon, NaN in the terrain, an unreadable file).

    """
    if not path:
        return Airspace()
    file = Path(path).expanduser()
    try:
        data = yaml.safe_load(file.read_text())
    except OSError as exc:
        raise InputError(f'airspace_file: cannot read {path} ({exc.strerror})') from None
    except yaml.YAMLError as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InputError(f'airspace_file {path}: not YAML ({first})') from None
    data = {} if data is None else data
    if not isinstance(data, dict):
        raise InputError(f'airspace_file {path}: expected a mapping with '
                         f'{" and/or ".join(AIRSPACE_FILE_KEYS)}')
    unknown = sorted(set(map(str, data)) - set(AIRSPACE_FILE_KEYS))
    if unknown:
        raise InputError(f'airspace_file {path}: unknown key {unknown[0]!r} (expected '
                         f'{" or ".join(AIRSPACE_FILE_KEYS)})')
    try:
        return Airspace.from_mapping(data, base=file.resolve().parent)
    except InputError as exc:
        raise InputError(f'airspace_file {path}: {exc}') from None


def airspace_of(zones: Sequence[Zone], terrain: Optional[Terrain]) -> Optional[Airspace]:
    """Return the airspace to plan in, or None when there is nothing to respect."""
    air = Airspace(tuple(zones), terrain)
    return air if air else None


def check_airspace_endpoints(start: NDArray, goal: NDArray,
                             airspace: Optional[Airspace]) -> None:
    """Refuse a start or goal inside a zone or below the terrain floor."""
    if airspace is not None:
        airspace.check_point('start', start)
        airspace.check_point('goal', goal)
