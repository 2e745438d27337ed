"""
Start the cloth simulation node, and RViz on request.

    ros2 launch hcloth_ros sim.launch.py
    ros2 launch hcloth_ros sim.launch.py params_file:=/path/to/fold.yaml rviz:=true
    ros2 launch hcloth_ros sim.launch.py rerun_path:=/tmp/run.rrd bag_path:=/tmp/run.mcap

The node's topics are relative (cloth/points, ...), so a ``namespace`` moves them; the
RViz configuration subscribes to the un-namespaced /cloth/... topics.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare


def generate_launch_description():
    """Declare the launch arguments; start sim_node and, if rviz is true, rviz2."""
    share = FindPackageShare('hcloth_ros')
    params_file = LaunchConfiguration('params_file')
    namespace = LaunchConfiguration('namespace')
    use_sim_time = LaunchConfiguration('use_sim_time')
    rerun_path = LaunchConfiguration('rerun_path')
    bag_path = LaunchConfiguration('bag_path')
    rviz = LaunchConfiguration('rviz')
    return LaunchDescription([
        DeclareLaunchArgument(
            'params_file',
            default_value=PathJoinSubstitution([share, 'config', 'hanging.yaml']),
            description='parameter file of the node (its entries are keyed /** so they '
                        'apply under any node name and namespace)'),
        DeclareLaunchArgument(
            'namespace', default_value='',
            description='namespace of the node and its topics (the RViz configuration '
                        'shows the un-namespaced /cloth/... topics)'),
        DeclareLaunchArgument(
            'use_sim_time', default_value='false',
            description='the node publishes /clock itself; true: its own ROS clock '
                        'follows it (its messages carry the simulated time either way)'),
        DeclareLaunchArgument(
            'rerun_path', default_value='',
            description='record the run to this .rrd file (empty: no recording)'),
        DeclareLaunchArgument(
            'bag_path', default_value='',
            description="record the node's topics to this MCAP file (empty: no bag)"),
        DeclareLaunchArgument(
            'rviz', default_value='false',
            description='true: also start rviz2 with the configuration of this package'),
        Node(
            package='hcloth_ros', executable='sim_node', name='hcloth_sim',
            namespace=namespace,
            # launch_ros YAML-parses substituted values in a parameters dict: a path such
            # as 'true' or '2024' would reach the node as a bool or an int, and
            # use_sim_time:=1 as an int that rclpy refuses; each value gets its type here
            parameters=[params_file, {
                'use_sim_time': ParameterValue(use_sim_time, value_type=bool),
                'rerun_path': ParameterValue(rerun_path, value_type=str),
                'bag_path': ParameterValue(bag_path, value_type=str),
            }],
            output='screen'),
        Node(
            package='rviz2', executable='rviz2', name='rviz2',
            arguments=['-d', PathJoinSubstitution([share, 'rviz', 'hcloth.rviz'])],
            # the node stamps every message with the simulated time, whatever its
            # use_sim_time: RViz's clock follows /clock so that the stamps match it
            parameters=[{'use_sim_time': True}],
            condition=IfCondition(rviz),
            output='screen'),
    ])
