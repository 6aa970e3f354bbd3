"""ROS 2 node ``compensator``: raw gyro Imu + Temperature in, corrected Imu out.

Thin glue around :class:`fog_temp_comp.core.compensator.Compensator`: messages are converted to
floats (stamps in s, rates in rad/s, temperature in degC), the core does the rest, and its status
is published on ``/diagnostics``.

Topics (remappable): ``imu/data_raw`` (sensor_msgs/Imu, in), ``imu/temperature``
(sensor_msgs/Temperature, in), ``imu/data`` (sensor_msgs/Imu, out), ``/diagnostics``
(diagnostic_msgs/DiagnosticArray, out); with ``rest_learning`` also ``imu/at_rest``
(std_msgs/Bool, in) and the service ``~/learn_bias_now`` (std_srvs/Trigger). The inputs are
subscribed best effort (the gyro keeping its newest 100 messages, the temperature 5); the
corrected Imu is published reliable, keep last 100 (REP 2003: any subscriber receives it).
Reliability and depth can be overridden per topic with the standard ``qos_overrides``
parameters.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any

from rclpy.node import Node

from fog_temp_comp.ros.compensator_shell import (
    IMU_INPUT_DEPTH,
    IMU_INPUT_QOS,
    OUTPUT_QOS,
    CompensatorShell,
)
from fog_temp_comp.ros.node_parameters import (
    FILTER_PARAMETERS,
    GUARD_PARAMETERS,
    REST_EARTH_PARAMETERS,
    REST_PARAMETERS,
    Config,
    resolve_path,
)
from fog_temp_comp.ros.spin import EXECUTORS, make_executor, run

__all__ = [
    'EXECUTORS',
    'FILTER_PARAMETERS',
    'GUARD_PARAMETERS',
    'IMU_INPUT_DEPTH',
    'IMU_INPUT_QOS',
    'OUTPUT_QOS',
    'REST_EARTH_PARAMETERS',
    'REST_PARAMETERS',
    'CompensatorNode',
    'CompensatorShell',
    'Config',
    'main',
    'make_executor',
    'resolve_path',
    'run',
]


class CompensatorNode(CompensatorShell, Node):
    """Subscribes raw gyro rate and temperature, publishes the drift-corrected Imu."""

    def __init__(
        self,
        node_name: str = 'fog_temp_compensator',
        *,
        params_file_paths: Sequence[str] = (),
        **kwargs: Any,
    ) -> None:
        super().__init__(node_name, **kwargs)
        self._setup_parameters(params_file_paths, kwargs.get('cli_args'))
        self._configure()
        self._log_config('started')
        self._create_io()


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of ``ros2 run fog_temp_comp compensator``."""
    return run(CompensatorNode, args, about=__doc__ or '')


if __name__ == '__main__':
    sys.exit(main())
