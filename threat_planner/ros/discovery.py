"""Fast DDS discovery of the package's executables: announce every 0.25 s, not every 3 s.

A participant that starts beside a running one is sometimes found only at the running
one's next periodic announcement (Fast DDS 2.14, a probe subscribing to a publisher running
for 3 s: 1.1-2.7 s in 4-7 of 14 starts with the default period of 3 s, none of 14 with
0.25 s on the running side; ``bench/results/dds_discovery.md``). Each executable of this
package therefore loads :data:`PROFILE` before rclpy starts, unless the user chose
otherwise:

* ``THREAT_PLANNER_DDS_PROFILE=0`` (or ``false``, ``off``) keeps Fast DDS's defaults;
* a profile file of the user's (``FASTRTPS_DEFAULT_PROFILES_FILE``,
  ``FASTDDS_DEFAULT_PROFILES_FILE``, or ``DEFAULT_FASTRTPS_PROFILES.xml`` /
  ``DEFAULT_FASTDDS_PROFILES.xml`` in the working folder), a discovery server
  (``ROS_DISCOVERY_SERVER``) or another RMW than Fast DDS is left alone.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping, MutableMapping, Optional

__all__ = ['PROFILE', 'PROFILE_VARIABLES', 'SWITCH', 'apply_discovery_profile',
           'discovery_profile_refusal']

#: The profile: after Fast DDS's initial announcements, one every 0.25 s (not 3 s).
PROFILE = Path(__file__).resolve().with_name('fastdds_discovery.xml')
#: Fast DDS 2.x (Jazzy) reads the first, 3.x the second.
PROFILE_VARIABLES = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE')
#: Set to 0, false or off to keep Fast DDS's own discovery timing.
SWITCH = 'THREAT_PLANNER_DDS_PROFILE'
_FAST_DDS = ('rmw_fastrtps_cpp', 'rmw_fastrtps_dynamic_cpp')
_DEFAULT_FILES = ('DEFAULT_FASTRTPS_PROFILES.xml', 'DEFAULT_FASTDDS_PROFILES.xml')


def discovery_profile_refusal(environ: Mapping[str, str],
                              cwd: Optional[Path] = None) -> Optional[str]:
    """Return why :data:`PROFILE` must not be loaded here, or None if it may.

    Parameters
    ----------
    environ : mapping
        The process environment.
    cwd : Path, optional
        Working folder (Fast DDS loads a default profile file from it); the current one
        if None.

    """
    if environ.get(SWITCH, '').strip().lower() in ('0', 'false', 'off', 'no'):
        return f'{SWITCH}={environ[SWITCH]}'
    rmw = environ.get('RMW_IMPLEMENTATION', '')
    if rmw and rmw not in _FAST_DDS:
        return f'RMW_IMPLEMENTATION={rmw}'
    for name in PROFILE_VARIABLES + ('ROS_DISCOVERY_SERVER',):
        if environ.get(name):
            return f'{name} is set'
    if not PROFILE.is_file():
        return f'{PROFILE} is missing'
    folder = Path.cwd() if cwd is None else cwd
    for name in _DEFAULT_FILES:
        if (folder / name).is_file():
            return f'{name} in the working folder'
    return None


def apply_discovery_profile(environ: MutableMapping[str, str] = os.environ,
                            cwd: Optional[Path] = None) -> Optional[str]:
    """Point Fast DDS at :data:`PROFILE` unless refused; call before ``rclpy.init``.

    Returns
    -------
    str or None
        None if the profile was set, else the refusal.

    """
    refusal = discovery_profile_refusal(environ, cwd)
    if refusal is None:
        for name in PROFILE_VARIABLES:
            environ[name] = str(PROFILE)
    return refusal
