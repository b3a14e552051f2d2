"""package.xml names every run-time dependency by its rosdep key, so ``rosdep install`` works.

The tables below are where a new dependency gets its key: adding one to setup.py, or an
import of a new package to the code, fails here until it has a row. Keys checked in
ros/rosdistro at 8468e88: ``rosdep/python.yaml`` for the ``python3-*`` and pip keys,
``jazzy/distribution.yaml`` for the ROS packages. None: rosdistro has no key (package.xml
says so in a comment); pip installs it from setup.py.
"""

import ast
from pathlib import Path
import re
import sys
import xml.etree.ElementTree as ET

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = ROOT / 'package.xml'

#: setup.py's requirement (name only) -> its rosdep key.
REQUIREMENTS = {
    'setuptools': 'python3-setuptools',    # builds the package: a buildtool_depend
    'numpy': 'python3-numpy',
    'scipy': 'python3-scipy',
    'networkx': 'python3-networkx',
    'PyYAML': 'python3-yaml',
    'matplotlib': 'python3-matplotlib',
    'tqdm': 'python3-tqdm',
    'threadpoolctl': None,
    'numba': 'python3-numba',
    'pyarrow': None,
    'ros-jazzy-rclpy': 'rclpy',
    'ros-jazzy-geometry-msgs': 'geometry_msgs',
    'ros-jazzy-nav-msgs': 'nav_msgs',
    'ros-jazzy-sensor-msgs': 'sensor_msgs',
    'ros-jazzy-visualization-msgs': 'visualization_msgs',
    'ros-jazzy-std-msgs': 'std_msgs',
    'ros-jazzy-diagnostic-msgs': 'diagnostic_msgs',
    'ros-jazzy-lifecycle-msgs': 'lifecycle_msgs',
    'mcap': None,                          # comes with mcap-ros2-support's pip key
    'mcap-ros2-support': 'mcap-ros2-support',
    'pymap3d': 'python3-pymap3d',
    'rasterio': 'python3-rasterio',
    'pyproj': 'python3-pyproj',
    'ray': None,
}
#: The extras a user's processes import (test and bench are the developers').
RUNTIME_EXTRAS = ('ros', 'record', 'geo', 'cluster')
#: Built with, never imported.
BUILD_ONLY = {'setuptools'}

#: Every package the installed code imports (top-level name) -> its rosdep key. The ROS
#: packages that are no setup.py line (rclpy's wheels bring them) are declared too.
IMPORTS = {
    'numpy': 'python3-numpy', 'scipy': 'python3-scipy', 'networkx': 'python3-networkx',
    'yaml': 'python3-yaml', 'matplotlib': 'python3-matplotlib', 'tqdm': 'python3-tqdm',
    'threadpoolctl': None, 'numba': 'python3-numba', 'pyarrow': None, 'mcap': None,
    'mcap_ros2': 'mcap-ros2-support', 'pymap3d': 'python3-pymap3d',
    'rasterio': 'python3-rasterio', 'pyproj': 'python3-pyproj', 'ray': None,
    'rclpy': 'rclpy', 'builtin_interfaces': 'builtin_interfaces',
    'geometry_msgs': 'geometry_msgs', 'nav_msgs': 'nav_msgs', 'sensor_msgs': 'sensor_msgs',
    'visualization_msgs': 'visualization_msgs', 'std_msgs': 'std_msgs',
    'diagnostic_msgs': 'diagnostic_msgs', 'rcl_interfaces': 'rcl_interfaces',
    'rosidl_runtime_py': 'rosidl_runtime_py', 'ament_index_python': 'ament_index_python',
    'launch': 'launch', 'launch_ros': 'launch_ros',
}


def setup_requirements() -> list[str]:
    """Return install_requires and the run-time extras' entries, names only, from setup.py."""
    call = next(node for node in ast.walk(ast.parse((ROOT / 'setup.py').read_text()))
                if isinstance(node, ast.Call) and getattr(node.func, 'id', '') == 'setup')
    args = {k.arg: k.value for k in call.keywords}
    extras = ast.literal_eval(args['extras_require'])
    found = ast.literal_eval(args['install_requires'])
    found += [r for name in RUNTIME_EXTRAS for r in extras[name]]
    return [re.match(r'[A-Za-z0-9._-]+', r).group(0) for r in found]


def imported_packages(*folders: str) -> set[str]:
    """Return the top-level names of the third-party packages the code in `folders` imports."""
    out = set()
    for folder in folders:
        for f in (ROOT / folder).rglob('*.py'):
            for node in ast.walk(ast.parse(f.read_text())):
                if isinstance(node, ast.Import):
                    out.update(a.name.split('.')[0] for a in node.names)
                elif isinstance(node, ast.ImportFrom) and node.level == 0:
                    out.add(node.module.split('.')[0])
    return out - set(sys.stdlib_module_names) - {'threat_planner', '__future__'}


def declared(tag: str, text: str | None = None) -> set[str]:
    """Return the keys of package.xml's `tag` elements (and of ``<depend>``)."""
    root = ET.fromstring(MANIFEST.read_text() if text is None else text)
    return {e.text.strip() for t in (tag, 'depend') for e in root.iter(t)}


def keyless_in_comments(text: str | None = None) -> str:
    """Return package.xml's comments that say a dependency has no key, as one text."""
    text = MANIFEST.read_text() if text is None else text
    return ' '.join(c for c in re.findall(r'<!--(.*?)-->', text, re.S)
                    if re.search(r'\bno (rosdep )?key\b', c, re.I))


def missing(table: dict, names, text: str | None = None) -> list[str]:
    """Return what `names` lacks in package.xml: no row in `table`, or its key undeclared."""
    run, build = declared('exec_depend', text), declared('buildtool_depend', text)
    keyless = keyless_in_comments(text)
    out = []
    for name in sorted(set(names)):
        if name not in table:
            out.append(f'{name}: no row in the table of test_package_xml.py')
        elif table[name] is None:
            if not re.search(rf'\b{re.escape(name)}\b', keyless):
                out.append(f'{name}: no rosdep key, and no package.xml comment says so')
        elif table[name] not in (build if name in BUILD_ONLY else run):
            out.append(f'{name}: package.xml lacks its key {table[name]}')
    return out


def test_every_setup_py_run_time_requirement_has_its_rosdep_key_in_package_xml():
    assert missing(REQUIREMENTS, setup_requirements()) == []


def test_every_package_the_code_imports_has_its_rosdep_key_in_package_xml():
    found = imported_packages('threat_planner', 'launch')
    assert {'numba', 'pyarrow', 'rclpy', 'launch_ros'} <= found   # the walk sees them
    assert missing(IMPORTS, found) == []


def test_package_xml_declares_nothing_the_tables_do_not_explain():
    """A stale key (python3-threadpoolctl, which rosdistro never had) shows up here."""
    keys = set(REQUIREMENTS.values()) | set(IMPORTS.values())
    assert declared('exec_depend') - keys == set()


def test_the_check_fails_for_a_requirement_without_its_key():
    text = MANIFEST.read_text()
    assert missing(REQUIREMENTS, ['shapely']) == [
        'shapely: no row in the table of test_package_xml.py']
    without_numba = text.replace('<exec_depend>python3-numba</exec_depend>', '')
    assert missing(REQUIREMENTS, ['numba'], without_numba) == [
        'numba: package.xml lacks its key python3-numba']
    without_comments = re.sub(r'<!--.*?-->', '', text, flags=re.S)
    assert missing(REQUIREMENTS, ['pyarrow'], without_comments) == [
        'pyarrow: no rosdep key, and no package.xml comment says so']
