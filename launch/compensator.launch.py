"""Start the compensator node with the package's params file.

    ros2 launch fog_temp_comp compensator.launch.py coefficients_file:=/path/to/coeffs.yaml
    ros2 launch fog_temp_comp compensator.launch.py params_file:=my.yaml namespace:=fog_x

``params_file`` defaults to the installed ``config/compensator.yaml``; ``coefficients_file``
is required unless the params file names one (the shipped one does not), and overrides it.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def _compensator(context):
    parameters = [LaunchConfiguration('params_file').perform(context)]
    coefficients_file = LaunchConfiguration('coefficients_file').perform(context)
    if coefficients_file:
        parameters.append({'coefficients_file': coefficients_file})
    return [
        Node(
            package='fog_temp_comp',
            executable='compensator',
            name='fog_temp_compensator',
            namespace=LaunchConfiguration('namespace'),
            parameters=parameters,
            arguments=['--ros-args', '--log-level', LaunchConfiguration('log_level')],
            output='screen',
            emulate_tty=True,
        )
    ]


def generate_launch_description():
    """The compensator node and its launch arguments."""
    share = get_package_share_directory('fog_temp_comp')
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                'params_file',
                default_value=os.path.join(share, 'config', 'compensator.yaml'),
                description='params file of the node (--params-file)',
            ),
            DeclareLaunchArgument(
                'coefficients_file',
                default_value='',
                description='coefficients YAML from `fog-temp-comp calibrate` of your unit '
                '(required unless params_file sets it; the shipped one does not)',
            ),
            DeclareLaunchArgument(
                'namespace', default_value='', description='namespace of the topics'
            ),
            DeclareLaunchArgument(
                'log_level', default_value='info', description='console log level'
            ),
            OpaqueFunction(function=_compensator),
        ]
    )
