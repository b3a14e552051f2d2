"""Launch the threat planner with the test threat publisher.

    ros2 launch threat_planner planner.launch.py
    ros2 launch threat_planner planner.launch.py scenario:=/path/to/scenario.yaml \
        rate:=2.0 drift:=1.0 record:=/tmp/threat_planner_bags

The planner reads ``config/planner.yaml``; the publisher publishes the scenario's threats,
start and goal (once and latched with rate 0, else at ``rate`` Hz with ``drift`` m/s of
threat motion). Set ``publisher:=false`` to run the planner alone.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare


def generate_launch_description():
    """Planner node and threat publisher, sharing the launch namespace."""
    share = FindPackageShare('threat_planner')
    arguments = [
        DeclareLaunchArgument(
            'params_file', default_value=PathJoinSubstitution([share, 'config', 'planner.yaml']),
            description='Parameters file of the planner node'),
        DeclareLaunchArgument(
            'scenario',
            default_value=PathJoinSubstitution([share, 'scenarios', 'uniform20_0.yaml']),
            description='Scenario YAML published by the threat publisher'),
        DeclareLaunchArgument('publisher', default_value='true',
                              description='Start the threat publisher'),
        DeclareLaunchArgument('rate', default_value='0.0',
                              description='Publication rate [Hz]; 0 = once, latched'),
        DeclareLaunchArgument('drift', default_value='0.0',
                              description='Threat motion [m/s] between publications'),
        DeclareLaunchArgument('use_pose_array', default_value='false',
                              description='Publish threats as a PoseArray'),
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
        output='screen', emulate_tty=True, condition=IfCondition(LaunchConfiguration('publisher')),
        parameters=[{
            'scenario': ParameterValue(LaunchConfiguration('scenario'), value_type=str),
            'rate': ParameterValue(LaunchConfiguration('rate'), value_type=float),
            'drift': ParameterValue(LaunchConfiguration('drift'), value_type=float),
            'use_pose_array': ParameterValue(LaunchConfiguration('use_pose_array'),
                                             value_type=bool),
        }])
    return LaunchDescription(arguments + [planner, publisher])
