"""Launch a simulated flight: the planner, the threat publisher playing events, the vehicle.

    ros2 launch threat_planner flight.launch.py
    ros2 launch threat_planner flight.launch.py scenario:=/path/to/scenario.yaml \
        events_file:=/path/to/events.yaml start:='[0.0, 0.0, 79.4]' \
        start_heading:='[45.0, -7.1]' record:=/tmp/flight.mcap

The planner reads ``config/planner.yaml`` and plans from the vehicle's ``odom``; the
publisher publishes the scenario's threats, start and goal and plays ``events_file`` from
its start (pop-ups, moves, removals, goal changes at their times); ``sim_vehicle`` flies
the planner's ``path`` from ``start`` along ``start_heading`` ([yaw, pitch] deg) and
publishes ``odom`` at ``rate_hz``. The defaults fly ``uniform20_0`` from its start towards
its goal. Its speed and limits are the planner's defaults: keep them equal to the
params file's.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare


def generate_launch_description():
    """Planner node, threat publisher and simulated vehicle, sharing the launch namespace."""
    share = FindPackageShare('threat_planner')
    arguments = [
        DeclareLaunchArgument(
            'params_file', default_value=PathJoinSubstitution([share, 'config', 'planner.yaml']),
            description='Parameters file of the planner node'),
        DeclareLaunchArgument(
            'scenario',
            default_value=PathJoinSubstitution([share, 'scenarios', 'uniform20_0.yaml']),
            description='Scenario YAML published by the threat publisher'),
        DeclareLaunchArgument('events_file', default_value='',
                              description="Events YAML played by the threat publisher; '' = "
                                          'none'),
        DeclareLaunchArgument('start', default_value='[0.0, 0.0, 79.39986235809553]',
                              description="The vehicle's start [x, y, z] (the scenario's)"),
        DeclareLaunchArgument('start_heading', default_value='[45.0, -7.1]',
                              description="The vehicle's initial [yaw, pitch] [deg]"),
        DeclareLaunchArgument('rate_hz', default_value='20.0',
                              description='Odometry rate of the vehicle [Hz]'),
        DeclareLaunchArgument('record', default_value='',
                              description="MCAP recording (file.mcap or folder); '' = off"),
    ]
    planner = Node(
        package='threat_planner', executable='planner_node', name='threat_planner',
        output='screen', emulate_tty=True,
        parameters=[LaunchConfiguration('params_file'),
                    {'record': ParameterValue(LaunchConfiguration('record'), value_type=str)}])
    publisher = Node(
        package='threat_planner', executable='threat_publisher', name='threat_publisher',
        output='screen', emulate_tty=True,
        parameters=[{
            'scenario': ParameterValue(LaunchConfiguration('scenario'), value_type=str),
            'events_file': ParameterValue(LaunchConfiguration('events_file'), value_type=str),
        }])
    vehicle = Node(
        package='threat_planner', executable='sim_vehicle', name='sim_vehicle',
        output='screen', emulate_tty=True,
        parameters=[{
            'start': LaunchConfiguration('start'),
            'start_heading': LaunchConfiguration('start_heading'),
            'rate_hz': ParameterValue(LaunchConfiguration('rate_hz'), value_type=float),
        }])
    return LaunchDescription(arguments + [planner, publisher, vehicle])
