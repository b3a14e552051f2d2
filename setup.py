from glob import glob
import os
import subprocess
import sys
import xml.etree.ElementTree as ET

from setuptools import find_packages, setup
from setuptools.command.build_py import build_py
from setuptools.command.develop import develop

package_name = 'threat_planner'
HERE = os.path.dirname(os.path.abspath(__file__))


def package_version(manifest=os.path.join(HERE, 'package.xml')):
    """Return ``<version>`` of package.xml, the one place the version is written.

    ROS's tools (bloom, catkin_pkg, rosdep) read it there; threat_planner.__version__ and
    ``threat-planner --version`` read the same file or the metadata built from it. A
    manifest without a version, or another package's, stops the build with the reason.
    """
    root = ET.parse(manifest).getroot()
    name = (root.findtext('name') or '').strip()
    found = (root.findtext('version') or '').strip()
    if name != package_name or not found:
        raise SystemExit(f'{manifest}: expected <name>{package_name}</name> and a '
                         f'<version>, found name {name!r}, version {found!r}')
    return found


def compile_kernels(where):
    """Compile the numba kernels into the user cache from the package at `where`.

    The cache is keyed by the kernels' contents, not their path, so what this compiles
    serves every install of the same sources (colcon, pip, the checkout). Where numba is
    not importable (pip's isolated build environment) or THREAT_PLANNER_NO_COMPILE is
    set, it says so and the build goes on: the first plan then compiles. After the JIT
    cache it builds the ahead-of-time module, beside it (53 s for both on 2 cores;
    THREAT_PLANNER_AOT_BUILD=0 skips it), or says in its line why not.
    """
    if os.environ.get('THREAT_PLANNER_NO_COMPILE'):
        return
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(where)] + [p for p in [os.environ.get('PYTHONPATH')] if p]))
    code = subprocess.call([sys.executable, '-c',
                            'from threat_planner.core.compiled import compile_all; '
                            'print("threat_planner:", compile_all().line())'], env=env)
    if code:
        print('threat_planner: kernels not compiled at build time (numba not importable '
              'here); run `threat-planner compile` once after installing', file=sys.stderr)


class BuildAndCompile(build_py):
    """``build_py`` (setup.py build, colcon build, pip wheel), then compile the kernels."""

    def run(self):
        super().run()
        compile_kernels(os.path.abspath(self.build_lib))


class DevelopAndCompile(develop):
    """``develop`` (colcon build --symlink-install), then compile the kernels."""

    def run(self):
        super().run()
        compile_kernels(os.path.dirname(os.path.abspath(__file__)))


setup(
    name=package_name,
    version=package_version(),
    packages=find_packages(exclude=['test', 'bench', 'bench.*']),
    # the Fast DDS discovery profile the executables load (threat_planner/ros/discovery.py)
    package_data={'threat_planner.ros': ['fastdds_discovery.xml']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/rviz', glob('rviz/*.rviz')),
        ('share/' + package_name + '/foxglove', glob('foxglove/*.json')),
        ('share/' + package_name + '/scenarios', glob('test/data/*.yaml')),
    ],
    install_requires=['setuptools', 'numpy', 'scipy', 'networkx', 'PyYAML', 'matplotlib', 'tqdm',
                      'threadpoolctl',
                      # the minor release tested here; python -m bench numba_newest runs
                      # the newest beside it (bench/results/numba_newest.md)
                      'numba>=0.68,<0.69', 'pyarrow'],
    extras_require={
        'ros': [
            'ros-jazzy-rclpy[fastrtps]',
            'ros-jazzy-geometry-msgs',
            'ros-jazzy-nav-msgs',
            'ros-jazzy-sensor-msgs',
            'ros-jazzy-visualization-msgs',
            'ros-jazzy-std-msgs',
            'ros-jazzy-diagnostic-msgs',
            'ros-jazzy-lifecycle-msgs',
        ],
        # mcap 1.6's public Writer.flush ends a chunk: the recorder's crash-safety flush
        'record': ['mcap>=1.6', 'mcap-ros2-support'],
        'test': ['pytest', 'pytest-xdist', 'hypothesis', 'flake8', 'pydocstyle', 'rosbags',
                 'colcon-core', 'colcon-ros', 'colcon-python-setup-py',
                 # readers of the exports (issue 26): ArduPilot / QGC files, MAVSDK, GeoJSON
                 'pymavlink', 'mavsdk', 'geojson'],
        # WGS84 scenarios, DEM terrain and exports (issue 26; loaded only when used)
        'geo': ['pymap3d', 'rasterio', 'pyproj'],
        'bench': ['ompl'],
        # threat-planner batch --ray (the tests start a local Ray cluster too)
        'cluster': ['ray'],
    },
    cmdclass={'build_py': BuildAndCompile, 'develop': DevelopAndCompile},
    zip_safe=True,
    maintainer='threat_planner maintainers',
    maintainer_email='maintainers@users.noreply.h-seed-a7c681e7.example',
    description='Threat-aware 3-D UAV path planner (Delaunay incentre network, Dijkstra, '
                'potential-field smoothing, direct cost optimisation).',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'threat-planner = threat_planner.cli.main:console',
            'planner_node = threat_planner.ros.entry:planner_node',
            'planner_lifecycle_node = threat_planner.ros.entry:planner_lifecycle_node',
            'threat_publisher = threat_planner.ros.publisher:main',
            'sim_vehicle = threat_planner.ros.sim_vehicle:main',
            'threat_planner_demo = threat_planner.cli.demo:main',
        ],
    },
)
