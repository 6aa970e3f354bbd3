"""ROS 2 node ``compensator``: raw gyro Imu + Temperature in, corrected Imu out.

Thin glue around :class:`fog_temp_comp.compensator.Compensator`: messages are converted to
floats (stamps in s, rates in rad/s, temperature in degC), the core does the rest.

Topics (remappable): ``imu/data_raw`` (sensor_msgs/Imu, in), ``imu/temperature``
(sensor_msgs/Temperature, in), ``imu/data`` (sensor_msgs/Imu, out). Sensor-data QoS; reliability
and depth can be overridden per topic with the standard ``qos_overrides`` parameters.
"""

from __future__ import annotations

import dataclasses
import os
import sys
from collections.abc import Sequence
from typing import Any

import rclpy
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
)
from rclpy.exceptions import ParameterUninitializedException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import Imu, Temperature

from fog_temp_comp.coefficients import Coefficients, CoefficientsError, load
from fog_temp_comp.compensator import Compensator
from fog_temp_comp.denoise import (
    BOUNDARY_MODES,
    METHODS,
    THRESHOLD_MODES,
    THRESHOLD_RULES,
    DenoiseSettings,
)

#: filter parameters: name -> (DenoiseSettings field, type, description)
FILTER_PARAMETERS: dict[str, tuple[str, Parameter.Type, str]] = {
    'denoise': ('method', Parameter.Type.STRING, f'Tdot denoising, one of {METHODS}'),
    'tdot_period_s': (
        'tdot_period_s',
        Parameter.Type.DOUBLE,
        'grid period on which Tdot is estimated (s); the paper uses 10 s',
    ),
    'wavelet': ('wavelet', Parameter.Type.STRING, 'PyWavelets name, e.g. sym8'),
    'wavelet_level': ('wavelet_level', Parameter.Type.INTEGER, 'wavelet decomposition levels'),
    'threshold_rule': (
        'threshold_rule',
        Parameter.Type.STRING,
        f'wavelet threshold rule, one of {THRESHOLD_RULES}',
    ),
    'threshold_mode': (
        'threshold_mode',
        Parameter.Type.STRING,
        f'wavelet thresholding, one of {THRESHOLD_MODES}',
    ),
    'boundary_mode': (
        'boundary_mode',
        Parameter.Type.STRING,
        f'wavelet signal extension, one of {BOUNDARY_MODES}',
    ),
    'window_samples': (
        'window_samples',
        Parameter.Type.INTEGER,
        'sliding wavelet window (Tdot samples)',
    ),
    'delay_samples': (
        'delay_samples',
        Parameter.Type.INTEGER,
        'wavelet output delay (Tdot samples); 0 = newest sample',
    ),
    'iir_order': ('iir_order', Parameter.Type.INTEGER, 'Butterworth order'),
    'iir_cutoff_hz': ('iir_cutoff_hz', Parameter.Type.DOUBLE, 'Butterworth cut-off (Hz)'),
}


def resolve_path(path: str) -> str:
    """Resolve ``package://<pkg>/<relative path>`` in the package's share directory."""
    prefix = 'package://'
    if not path.startswith(prefix):
        return path
    package, _, relative = path[len(prefix) :].partition('/')
    from ament_index_python.packages import (
        PackageNotFoundError,
        get_package_share_directory,
    )

    try:
        share = get_package_share_directory(package)
    except PackageNotFoundError:
        raise CoefficientsError(
            f'coefficients_file {path}: package {package!r} is not installed (AMENT_PREFIX_PATH)'
        ) from None
    return os.path.join(share, relative)


class CompensatorNode(Node):
    """Subscribes raw gyro rate and temperature, publishes the drift-corrected Imu."""

    def __init__(self, node_name: str = 'fog_temp_compensator', **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.declare_parameter(
            'coefficients_file',
            '',
            ParameterDescriptor(
                description='coefficients YAML written by `fog-temp-comp calibrate` (required; '
                'a path, or package://<pkg>/<path in its share directory>)',
                read_only=True,
            ),
        )
        for name, (_, ptype, text) in FILTER_PARAMETERS.items():
            descriptor = ParameterDescriptor(
                description=text + '; unset = as stored in the coefficients file',
                read_only=True,
            )
            if name in ('tdot_period_s', 'iir_cutoff_hz'):
                descriptor.floating_point_range = [
                    FloatingPointRange(from_value=0.0, to_value=3600.0, step=0.0)
                ]
            if ptype == Parameter.Type.INTEGER:
                descriptor.integer_range = [IntegerRange(from_value=0, to_value=1 << 20, step=1)]
            self.declare_parameter(name, ptype, descriptor)

        path = self.get_parameter('coefficients_file').value
        if not path:
            raise CoefficientsError('parameter coefficients_file is not set')
        self.coefficients: Coefficients = load(resolve_path(path))
        self.settings = self._settings_from_parameters(self.coefficients.denoise)
        self.compensator = Compensator(self.coefficients.model, self.settings)
        self.get_logger().info(
            f'coefficients {path} (frame {self.coefficients.frame_id or "any"}), Tdot denoise '
            f'{self.settings.method}'
        )

        qos_options = QoSOverridingOptions.with_default_policies()
        self._publisher = self.create_publisher(
            Imu, 'imu/data', qos_profile_sensor_data, qos_overriding_options=qos_options
        )
        self._imu_sub = self.create_subscription(
            Imu,
            'imu/data_raw',
            self._on_imu,
            qos_profile_sensor_data,
            qos_overriding_options=qos_options,
        )
        self._temp_sub = self.create_subscription(
            Temperature,
            'imu/temperature',
            self._on_temperature,
            qos_profile_sensor_data,
            qos_overriding_options=qos_options,
        )

    def _settings_from_parameters(self, base: DenoiseSettings) -> DenoiseSettings:
        overrides = {}
        for name, (field, _, _) in FILTER_PARAMETERS.items():
            try:
                value = self.get_parameter(name).value
            except ParameterUninitializedException:
                continue
            if value is not None:
                overrides[field] = value
        return dataclasses.replace(base, **overrides)

    def _on_temperature(self, msg: Temperature) -> None:
        stamp = msg.header.stamp
        self.compensator.add_temperature(stamp.sec + stamp.nanosec * 1e-9, msg.temperature)

    def _on_imu(self, msg: Imu) -> None:
        stamp = msg.header.stamp
        w = msg.angular_velocity
        rate = self.compensator.correct(stamp.sec + stamp.nanosec * 1e-9, (w.x, w.y, w.z))
        w.x, w.y, w.z = float(rate[0]), float(rate[1]), float(rate[2])
        self._publisher.publish(msg)


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of ``ros2 run fog_temp_comp compensator``."""
    rclpy.init(args=None if args is None else list(args))
    node = None
    try:
        node = CompensatorNode()
        rclpy.spin(node)
    except (CoefficientsError, ValueError) as err:
        print(f'ERROR: {err}', file=sys.stderr)
        return 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
