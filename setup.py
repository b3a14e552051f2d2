from glob import glob

from setuptools import find_packages, setup

package_name = 'threat_planner'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'bench']),
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
                      'threadpoolctl', 'numba', 'pyarrow'],
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
        'record': ['mcap', 'mcap-ros2-support'],
        'test': ['pytest', 'hypothesis', 'flake8', 'pydocstyle', 'rosbags', 'colcon-core',
                 'colcon-ros', 'colcon-python-setup-py'],
        'bench': ['ompl'],
        # threat-planner batch --ray (the tests start a local Ray cluster too)
        'cluster': ['ray'],
    },
    zip_safe=True,
    maintainer='threat_planner maintainers',
    maintainer_email='maintainers@users.noreply.h-seed-a7c681e7.example',
    description='Threat-aware 3-D UAV path planner (Delaunay incentre network, Dijkstra, '
                'potential-field smoothing, direct cost optimisation).',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'threat-planner = threat_planner.cli.main:console',
            'planner_node = threat_planner.ros.node:main',
            'planner_lifecycle_node = threat_planner.ros.lifecycle:main',
            'threat_publisher = threat_planner.ros.publisher:main',
            'threat_planner_demo = threat_planner.cli.demo:main',
        ],
    },
)
