"""ROS 2 node ``compensator``: raw gyro Imu + Temperature in, corrected Imu out.

Thin glue around :class:`fog_temp_comp.core.compensator.Compensator`: messages are converted to
floats (stamps in s, rates in rad/s, temperature in degC), the core does the rest, and its status
is published on ``/diagnostics``.

Topics (remappable): ``imu/data_raw`` (sensor_msgs/Imu, in), ``imu/temperature``
(sensor_msgs/Temperature, in), ``imu/data`` (sensor_msgs/Imu, out), ``/diagnostics``
(diagnostic_msgs/DiagnosticArray, out); with ``rest_learning`` also ``imu/at_rest``
(std_msgs/Bool, in) and the service ``~/learn_bias_now`` (std_srvs/Trigger). Sensor-data QoS on
the data topics, except that the gyro input keeps the newest :data:`IMU_INPUT_DEPTH` messages,
not 5; reliability and depth can be overridden per topic with the standard ``qos_overrides``
parameters.
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy._rclpy_pybind11 import RCLError
from rclpy.exceptions import (
    InvalidParameterTypeException,
    InvalidParameterValueException,
    ParameterUninitializedException,
)
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import Imu, Temperature
from std_msgs.msg import Bool
from std_srvs.srv import Trigger

from fog_temp_comp.core.coefficients import Coefficients, CoefficientsError, load
from fog_temp_comp.core.compensator import STALE_POLICIES, Compensator, GuardSettings
from fog_temp_comp.core.denoise import (
    BOUNDARY_MODES,
    METHODS,
    THRESHOLD_MODES,
    THRESHOLD_RULES,
    DenoiseSettings,
)
from fog_temp_comp.core.earth import earth_rate_body_deg_h, parse_orientation
from fog_temp_comp.core.rest import REST_SOURCES, RestSettings
from fog_temp_comp.core.restfile import (
    LearnedBiasError,
    check_learned_bias,
    file_sha256,
    learned_bias_from_status,
    read_learned_bias,
    write_learned_bias,
)
from fog_temp_comp.core.units import AXES, RAD_S_PER_DEG_H
from fog_temp_comp.ros.diagnostics import build_report
from fog_temp_comp.ros.params import (
    ParameterError,
    expected_text,
    params_files,
    read_params_file,
    sections_warning,
    unknown_warnings,
)

_T = Parameter.Type
#: Tdot filter parameters, unset = as in the coefficients file: name -> (field, type, text)
FILTER_PARAMETERS: dict[str, tuple[str, Parameter.Type, str]] = {
    'denoise': ('method', _T.STRING, f'Tdot denoising, one of {METHODS}'),
    'tdot_period_s': ('tdot_period_s', _T.DOUBLE, 'grid period on which Tdot is estimated (s)'),
    'wavelet': ('wavelet', _T.STRING, 'PyWavelets wavelet name, e.g. sym8'),
    'wavelet_level': ('wavelet_level', _T.INTEGER, 'wavelet decomposition levels'),
    'threshold_rule': ('threshold_rule', _T.STRING, f'threshold rule, one of {THRESHOLD_RULES}'),
    'threshold_mode': ('threshold_mode', _T.STRING, f'thresholding, one of {THRESHOLD_MODES}'),
    'boundary_mode': ('boundary_mode', _T.STRING, f'signal extension, one of {BOUNDARY_MODES}'),
    'window_samples': ('window_samples', _T.INTEGER, 'sliding wavelet window (Tdot samples)'),
    'delay_samples': ('delay_samples', _T.INTEGER, 'wavelet read-out delay (Tdot samples)'),
    'iir_order': ('iir_order', _T.INTEGER, 'Butterworth order'),
    'iir_cutoff_hz': ('iir_cutoff_hz', _T.DOUBLE, 'Butterworth cut-off (Hz)'),
    'llr_window_s': ('llr_window_s', _T.DOUBLE, 'local linear regression window (s), llr'),
    'kalman_rate_walk_degC_per_min_per_sqrt_s': (
        'kalman_rate_walk_degC_per_min_per_sqrt_s',
        _T.DOUBLE,
        'how fast Tdot may change in the Kalman model (degC/min per sqrt(s)), kalman',
    ),
    'temperature_noise_degC': (
        'temperature_noise_degC',
        _T.DOUBLE,
        'temperature sensor white noise (degC), kalman',
    ),
    'temperature_quantum_degC': (
        'temperature_quantum_degC',
        _T.DOUBLE,
        'temperature sensor resolution (degC), kalman',
    ),
    'coil_lag_s': (
        'coil_lag_s',
        _T.DOUBLE,
        'first-order lag from the temperature sensor to the fibre coil (s), 0 = none',
    ),
    'tdot_lag_s': (
        'tdot_lag_s',
        _T.DOUBLE,
        'lag (s) making the Tdot_lag term (the lead-lag from sensor to coil), 0 = none',
    ),
    'tdot_shrink_sigmas': (
        'tdot_shrink_sigmas',
        _T.DOUBLE,
        'shrink Tdot toward 0 below this many posterior std (start-up, soaks), kalman; 0 = off',
    ),
}
_GUARD_DEFAULTS = GuardSettings()
#: input guards: name -> (default, text)
GUARD_PARAMETERS: dict[str, tuple[Any, str]] = {
    'temperature_timeout_s': (
        _GUARD_DEFAULTS.temperature_timeout_s,
        'temperature older than this (s) relative to a gyro stamp is stale',
    ),
    'stale_policy': (
        _GUARD_DEFAULTS.stale_policy,
        f'with stale temperature, one of {STALE_POLICIES}: hold the last correction or none',
    ),
    'clamp_temperature': (
        _GUARD_DEFAULTS.clamp_temperature,
        'clamp temperature to the calibrated range (else extrapolate, reported)',
    ),
    'clamp_tdot': (
        _GUARD_DEFAULTS.clamp_tdot,
        'clamp Tdot to the calibrated range (default off: the linear Tdot terms are applied '
        'beyond it up to tdot_limit_degC_per_min, reported)',
    ),
    'tdot_limit_degC_per_min': (
        _GUARD_DEFAULTS.tdot_limit_degC_per_min,
        'bound on |Tdot| fed to the model when clamp_tdot is off (degC/min)',
    ),
    'time_jump_threshold_s': (
        _GUARD_DEFAULTS.time_jump_threshold_s,
        'a stamp this far (s) behind the previous one resets the filter (bag loop, sim reset)',
    ),
    'max_temperature_step_degC': (
        _GUARD_DEFAULTS.max_temperature_step_degC,
        'temperature jump (degC) beyond which a sample is a glitch unless confirmed',
    ),
    'max_temperature_rate_degC_per_min': (
        _GUARD_DEFAULTS.max_temperature_rate_degC_per_min,
        'plausible temperature rate (degC/min) added to the glitch threshold',
    ),
}


_REST_DEFAULTS = RestSettings()
#: bias learning at rest (read-only): name -> (RestSettings field, default, text)
REST_PARAMETERS: dict[str, tuple[str, Any, str]] = {
    'rest_learning': (
        'enabled',
        False,
        'learn the residual constant bias per axis while at rest (off by default)',
    ),
    'rest_source': (
        'source',
        _REST_DEFAULTS.source,
        f'one of {REST_SOURCES}: rest from the Imu variance alone, or also the std_msgs/Bool '
        'topic imu/at_rest (true for the whole window)',
    ),
    'rest_window_s': ('window_s', _REST_DEFAULTS.window_s, 'rest detection window (s)'),
    'rest_gyro_std_max_deg_h': (
        'gyro_std_max_deg_h',
        _REST_DEFAULTS.gyro_std_max_deg_h,
        'largest gyro std in a rest window, each axis (deg/h)',
    ),
    'rest_accel_std_max_m_s2': (
        'accel_std_max_m_s2',
        _REST_DEFAULTS.accel_std_max_m_s2,
        'largest accelerometer std in a rest window, each axis (m/s^2)',
    ),
    'rest_accel_drift_max_m_s2': (
        'accel_drift_max_m_s2',
        _REST_DEFAULTS.accel_drift_max_m_s2,
        'largest change of the accelerometer mean between the window halves (m/s^2): a slow '
        'tilt (false rest) beyond it is detected',
    ),
    'rest_residual_limit_deg_h': (
        'residual_limit_deg_h',
        _REST_DEFAULTS.residual_limit_deg_h,
        'a rest residual above this on any axis is reported, not applied (deg/h)',
    ),
    'rest_time_constant_s': (
        'time_constant_s',
        _REST_DEFAULTS.time_constant_s,
        'the applied residual follows the learned one with this first-order lag (s)',
    ),
}
#: Earth rate for rest learning (read-only): name -> (default, text)
REST_EARTH_PARAMETERS: dict[str, tuple[Any, str]] = {
    'rest_earth_rate': (
        False,
        'subtract the Earth rate (rest_latitude_deg, rest_axes_orientation) from the rest '
        'residual; off: the Earth rate is learned into the constant (right only while the unit '
        'keeps its resting orientation)',
    ),
    'rest_latitude_deg': (0.0, 'latitude for rest_earth_rate (deg)'),
    'rest_axes_orientation': (
        'enu',
        'sensor axes in ENU at rest, for rest_earth_rate: enu, ned, nwu, ..., as calibrate',
    ),
    'rest_bias_file': (
        '',
        'YAML keeping the learned bias for the next start (empty = none): read at start / '
        'configure as the initial value (refused if learned with other coefficients or Earth '
        'rate, or above rest_residual_limit_deg_h), written on shutdown, deactivate, cleanup '
        'and after a learn_bias_now window',
    ),
}


@dataclass(frozen=True)
class Config:
    """Everything the compensator is built from."""

    coefficients_file: str
    coefficients: Coefficients
    settings: DenoiseSettings
    guard: GuardSettings
    rest: RestSettings
    rest_bias_file: str = ''


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


#: history depth of the gyro subscription: 50 ms at 2 kHz. A dropped gyro sample is lost to the
#: attitude integration downstream, so the queue rides out scheduling hiccups (a GC pause, a
#: busy core) that a depth of 5 (2.5 ms at 2 kHz) cannot; ``benchmarks/bench_node.py``
IMU_INPUT_DEPTH = 100
#: values of the ``executor`` parameter
EXECUTORS = ('auto', 'events', 'single')
IMU_INPUT_QOS = QoSProfile(
    history=qos_profile_sensor_data.history,
    depth=IMU_INPUT_DEPTH,
    reliability=qos_profile_sensor_data.reliability,
    durability=qos_profile_sensor_data.durability,
)


if TYPE_CHECKING:  # the mixin is always combined with a Node: type it as one
    _NodeBase = Node
else:
    _NodeBase = object


class CompensatorShell(_NodeBase):
    """The ROS glue shared by :class:`CompensatorNode` and the lifecycle node.

    A mixin for an rclpy ``Node`` (or ``LifecycleNode``): parameters, the subscriptions and
    publishers around one :class:`Compensator`, console lines and diagnostics. The two nodes
    differ only in when they call :meth:`_setup_parameters`, :meth:`_configure`,
    :meth:`_create_io` and :meth:`_destroy_io`.
    """

    #: both None only while a lifecycle node is unconfigured, when none of the callbacks
    #: below runs (no subscription, no timer); typed for the configured state they run in
    config: Config
    compensator: Compensator

    def _setup_parameters(self, params_file_paths: Sequence[str], cli_args: Any) -> None:
        """Declare and check the parameters (raises :class:`ParameterError` on a bad one)."""
        self._check_params_files([*params_file_paths, *params_files(cli_args)])
        self._declare_parameters()
        executor = self.get_parameter('executor').value
        if executor not in EXECUTORS:
            raise ParameterError(
                f'parameter executor: expected one of {EXECUTORS}, got {executor!r}'
            )
        for line in unknown_warnings(self._given_parameters(), self._parameters):
            self.get_logger().warning(line)
        self._forget_compensator()
        self.reconfigurations = 0
        self.frame_mismatches = 0
        #: messages with an unset (0) header stamp, timed by the node clock instead
        self.unstamped = 0
        self._require_frame_match = bool(self.get_parameter('require_frame_id_match').value)
        self._inflate_covariance = bool(self.get_parameter('inflate_covariance').value)
        self._throttle_s = float(self.get_parameter('log_throttle_s').value)
        self._warm_up_start_s: float | None = None
        self._last_frame_mismatches = 0
        #: gyro messages are corrected and published only while this is set (lifecycle: active)
        self.output_enabled = True
        #: gyro messages ignored while output_enabled was off
        self.imu_while_inactive = 0
        self.add_on_set_parameters_callback(self._on_set_parameters)

    @property
    def configured(self) -> bool:
        """Whether the compensator exists (always for the plain node)."""
        return getattr(self, 'compensator', None) is not None

    def _forget_compensator(self) -> None:
        """Unconfigured: no coefficients, no compensator."""
        self.config = None  # type: ignore[assignment]
        self.compensator = None  # type: ignore[assignment]

    def _configure(self) -> None:
        """Load and validate the coefficients, build the compensator (raises on bad ones)."""
        self.config = self._build_config({})
        self.compensator = Compensator(
            self.config.coefficients.model,
            self.config.settings,
            self.config.guard,
            self.config.rest,
        )
        self._warm_up_start_s = None
        self._load_learned_bias()

    # ------------------------------------------------------------------ learned bias file
    def _load_learned_bias(self) -> None:
        """Start the bias learner from ``rest_bias_file`` if it holds a value for this model."""
        path = self.config.rest_bias_file
        self._rest_bias_state = ''
        self._forced_seen = 0
        self._forced_outcome_seen = ''
        rest = self.compensator.rest
        if rest is None or not path:
            return
        log = self.get_logger()
        if not os.path.exists(path):
            self._rest_bias_state = 'absent: starting from zero'
            log.info(f'rest_bias_file {path} does not exist yet: starting from zero')
            return
        try:
            bias = read_learned_bias(path)
            check_learned_bias(
                bias,
                coefficients_sha256=self._coefficients_sha256(),
                earth_rate_body_deg_h=self.config.rest.earth_rate_body_deg_h,
                path=path,
            )
        except (LearnedBiasError, OSError) as err:
            self._rest_bias_state = f'refused: {err}'
            log.warning(f'rest_bias_file not used, starting from zero: {err}')
            return
        reason = rest.start_from(bias.bias_deg_h)
        if reason is not None:
            self._rest_bias_state = f'refused: {reason}'
            log.warning(f'rest_bias_file {path}: {reason}; starting from zero')
            return
        text = ', '.join(f'{v:.3f}' for v in bias.bias_deg_h)
        self._rest_bias_state = f'loaded: {text} deg/h (x, y, z)'
        log.info(
            f'rest_bias_file {path}: starting from the learned bias {text} deg/h (x, y, z), '
            f'{bias.windows} windows at {bias.temperature_degC:.2f} degC'
        )

    def _coefficients_sha256(self) -> str:
        return file_sha256(resolve_path(self.config.coefficients_file))

    def save_learned_bias(self, why: str) -> bool:
        """Write what was learned in this run to ``rest_bias_file``; whether a file was written.

        Nothing is written without a file, without learning, or before a window was learned
        in this run (the file keeps the last turn-on's value). An error is logged, not raised.
        """
        rest = self.compensator.rest if self.configured else None
        path = self.config.rest_bias_file if self.configured else ''
        if rest is None or not path:
            return False
        try:
            bias = learned_bias_from_status(
                rest.finish(),
                self.config.rest,
                coefficients_file=self.config.coefficients_file,
                coefficients_sha256=self._coefficients_sha256(),
            )
            if bias is None:
                return False
            write_learned_bias(path, bias)
        except OSError as err:
            self._rest_bias_state = f'write failed ({why}): {err}'
            self.get_logger().error(f'rest_bias_file {path}: cannot write it ({why}): {err}')
            return False
        text = ', '.join(f'{v:.3f}' for v in bias.bias_deg_h)
        self._rest_bias_state = f'written ({why}): {text} deg/h (x, y, z)'
        self.get_logger().info(f'rest_bias_file {path} written ({why}): {text} deg/h (x, y, z)')
        return True

    def destroy_node(self) -> None:
        """Write the learned bias (shutdown), then destroy the node."""
        self.save_learned_bias('shutdown')
        super().destroy_node()

    # ------------------------------------------------------------------ learn now
    def _on_learn_now(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        """``~/learn_bias_now``: accept the next rest window without the rest checks."""
        reason = self._learn_now_refusal()
        if reason:
            response.success = False
            response.message = reason
            return response
        rest = self.compensator.rest
        assert rest is not None
        rest.force_next_window()
        st = rest.finish()
        settings = self.config.rest
        so_far = ', '.join(f'{v:.3f}' for v in st.learned_deg_h)
        response.success = True
        response.message = (
            f'armed: the next {settings.window_s:g} s window is learned without the rest '
            f'checks, if its residual is within {settings.residual_limit_deg_h:g} deg/h '
            f'(rest_residual_limit_deg_h); learned so far {so_far} deg/h (x, y, z) from '
            f'{st.windows_rest} windows; the outcome is logged and in /diagnostics '
            '(rest_forced_outcome)'
        )
        self.get_logger().info(f'learn_bias_now: {response.message}')
        return response

    def _learn_now_refusal(self) -> str:
        """Why "learn now" cannot be armed ('' if it can)."""
        if not self.configured or self.compensator.rest is None:
            return 'not configured'
        if not self.output_enabled:
            return 'inactive: no gyro is processed; activate the node first'
        status = self.compensator.status
        if not status.has_temperature or not status.estimator_ready:
            return (
                'the Tdot filter is not warmed up yet: the drift-corrected rate the bias is '
                'learned from is not available; call again once diagnostics say filter_ready'
            )
        if status.temperature_stale:
            return 'temperature stale: the drift-corrected rate is not available'
        return ''

    def _check_forced_window(self) -> None:
        """Log and save once a "learn now" window has been judged (diagnostics timer)."""
        rest = self.compensator.rest
        if rest is None:
            return
        st = rest.status
        if st.forced_outcome and st.forced_outcome != self._forced_outcome_seen:
            self._forced_outcome_seen = st.forced_outcome
            log = self.get_logger()
            if st.windows_forced > self._forced_seen:
                log.info(f'learn_bias_now: {st.forced_outcome}')
                self.save_learned_bias('learn_bias_now')
            else:
                log.warning(f'learn_bias_now: {st.forced_outcome}')
        self._forced_seen = st.windows_forced

    def _create_output(self, *args: Any, **kwargs: Any) -> Publisher:
        """The publisher of ``imu/data`` (the lifecycle node makes it a lifecycle publisher)."""
        return self.create_publisher(*args, **kwargs)

    def _destroy_output(self, publisher: Publisher) -> None:
        self.destroy_publisher(publisher)

    def _create_io(self) -> None:
        """Subscriptions, publishers and the diagnostics timer.

        ``/diagnostics`` is always a plain publisher, so the health stays visible while a
        lifecycle node is inactive.
        """
        qos_options = QoSOverridingOptions.with_default_policies()
        self._publisher = self._create_output(
            Imu, 'imu/data', qos_profile_sensor_data, qos_overriding_options=qos_options
        )
        self._imu_sub = self.create_subscription(
            Imu,
            'imu/data_raw',
            self._on_imu,
            IMU_INPUT_QOS,
            qos_overriding_options=qos_options,
        )
        self._temp_sub = self.create_subscription(
            Temperature,
            'imu/temperature',
            self._on_temperature,
            qos_profile_sensor_data,
            qos_overriding_options=qos_options,
        )
        self._rest_sub = None
        self._learn_srv = None
        if self.config.rest.enabled:
            self._rest_sub = self.create_subscription(Bool, 'imu/at_rest', self._on_at_rest, 10)
            self._learn_srv = self.create_service(Trigger, '~/learn_bias_now', self._on_learn_now)
        self._diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._last_counters = dataclasses.replace(self.compensator.status.counters)
        self._last_report_time = time.monotonic()
        period = self.get_parameter('diagnostics_period_s').value
        self._diag_timer = self.create_timer(period, self.publish_diagnostics)

    def _destroy_io(self) -> None:
        """Undo :meth:`_create_io`."""
        self.destroy_timer(self._diag_timer)
        self.destroy_subscription(self._imu_sub)
        self.destroy_subscription(self._temp_sub)
        self.destroy_publisher(self._diag_pub)
        if self._rest_sub is not None:
            self.destroy_subscription(self._rest_sub)
        if self._learn_srv is not None:
            self.destroy_service(self._learn_srv)
        self._destroy_output(self._publisher)

    # ------------------------------------------------------------------ parameters
    def _declare_parameters(self) -> None:
        self._declare(
            'coefficients_file',
            '',
            ParameterDescriptor(
                description='coefficients YAML from `fog-temp-comp calibrate` (required): a '
                'path, or package://<pkg>/<path in its share directory>; setting it reloads'
            ),
        )
        self._declare_table_parameters()
        self._declare(
            'require_frame_id_match',
            False,
            ParameterDescriptor(
                description='pass gyro messages whose frame_id differs from the calibrated '
                'one through uncorrected (else correct them and warn)'
            ),
        )
        self._declare(
            'inflate_covariance',
            False,
            ParameterDescriptor(
                description='add the calibration residual variance to the angular velocity '
                'covariance diagonal (when the covariance is known)'
            ),
        )
        self._declare(
            'executor',
            'auto',
            ParameterDescriptor(
                description="executor of `ros2 run`: 'events' (rclpy.experimental."
                'EventsExecutor, Jazzy and later: keeps up with a 2 kHz gyro), '
                "'single' (SingleThreadedExecutor), or 'auto' (events where rclpy has it, "
                "else single); 'events' without it falls back to single with a warning",
                read_only=True,
                additional_constraints="one of 'auto', 'events', 'single'",
            ),
        )
        self._declare(
            'diagnostics_period_s',
            1.0,
            ParameterDescriptor(
                description='period of /diagnostics (s)',
                read_only=True,
                floating_point_range=[FloatingPointRange(from_value=0.01, to_value=60.0)],
            ),
        )
        self._declare(
            'log_throttle_s',
            10.0,
            ParameterDescriptor(
                description='each kind of console warning is printed at most once per this '
                'many seconds (s)',
                read_only=True,
                floating_point_range=[FloatingPointRange(from_value=0.01, to_value=3600.0)],
            ),
        )

    def _declare_table_parameters(self) -> None:
        """The Tdot filter, guard and rest-learning parameters, from their tables."""
        for name, (_, ptype, text) in FILTER_PARAMETERS.items():
            descriptor = ParameterDescriptor(
                description=text + '; unset = as in the coefficients file; changing it '
                'restarts the Tdot filter'
            )
            if ptype == _T.DOUBLE:
                descriptor.floating_point_range = [
                    FloatingPointRange(from_value=0.0, to_value=3600.0, step=0.0)
                ]
            if ptype == _T.INTEGER:
                descriptor.integer_range = [IntegerRange(from_value=0, to_value=1 << 20, step=1)]
            self._declare(name, ptype, descriptor)
        for name, (default, text) in GUARD_PARAMETERS.items():
            descriptor = ParameterDescriptor(description=text)
            if isinstance(default, float):
                descriptor.floating_point_range = [
                    FloatingPointRange(from_value=0.001, to_value=1e6, step=0.0)
                ]
            self._declare(name, default, descriptor)
        for name, (_, default, text) in REST_PARAMETERS.items():
            descriptor = ParameterDescriptor(description=text, read_only=True)
            if isinstance(default, float):
                descriptor.floating_point_range = [
                    FloatingPointRange(from_value=1e-6, to_value=1e6, step=0.0)
                ]
            self._declare(name, default, descriptor)
        for name, (default, text) in REST_EARTH_PARAMETERS.items():
            descriptor = ParameterDescriptor(description=text, read_only=True)
            if name == 'rest_latitude_deg':
                descriptor.floating_point_range = [
                    FloatingPointRange(from_value=-90.0, to_value=90.0, step=0.0)
                ]
            self._declare(name, default, descriptor)

    def _declare(self, name: str, value: Any, descriptor: ParameterDescriptor) -> None:
        """Declare one parameter; a bad override raises a one-line :class:`ParameterError`."""
        try:
            self.declare_parameter(name, value, descriptor)
        except (InvalidParameterTypeException, InvalidParameterValueException):
            raise ParameterError(_bad_value_text(self, name, value, descriptor)) from None

    def _given_parameters(self) -> list[str]:
        """Names set for this node from the command line or a params file."""
        return list(getattr(self, '_parameter_overrides', {}))

    def _check_params_files(self, paths: Sequence[str]) -> None:
        """Warn about params files that set nothing for this node."""
        for path in paths:
            warning = sections_warning(
                path, read_params_file(path), self.get_fully_qualified_name()
            )
            if warning:
                self.get_logger().warning(warning)

    def _value(self, name: str, changes: dict[str, Parameter]) -> Any:
        if name in changes:
            return changes[name].value
        try:
            return self.get_parameter(name).value
        except ParameterUninitializedException:
            return None

    def _build_config(self, changes: dict[str, Parameter]) -> Config:
        """Config from the current parameters with ``changes`` applied; raises on bad values."""
        path = self._value('coefficients_file', changes)
        if not path:
            raise CoefficientsError('parameter coefficients_file is not set')
        coefficients = load(resolve_path(path))
        overrides = {}
        for name, (field, _, _) in FILTER_PARAMETERS.items():
            value = self._value(name, changes)
            if value is not None:
                overrides[field] = value
        if overrides.get('method', METHODS[0]) not in METHODS:
            raise ParameterError(
                f'parameter denoise: expected one of {METHODS}, got {overrides["method"]!r}'
            )
        settings = dataclasses.replace(coefficients.denoise, **overrides)
        guard = GuardSettings(**{name: self._value(name, changes) for name in GUARD_PARAMETERS})
        rest_bias_file = str(self._value('rest_bias_file', {}) or '')
        return Config(path, coefficients, settings, guard, self._rest_settings(), rest_bias_file)

    def _rest_settings(self) -> RestSettings:
        """Bias learning at rest from its (read-only) parameters; raises ValueError."""
        fields = {f: self._value(name, {}) for name, (f, _, _) in REST_PARAMETERS.items()}
        if self._value('rest_earth_rate', {}):
            orientation = parse_orientation(str(self._value('rest_axes_orientation', {})))
            latitude_deg = float(self._value('rest_latitude_deg', {}))
            earth = earth_rate_body_deg_h(latitude_deg, orientation)
            fields['earth_rate_body_deg_h'] = tuple(float(v) for v in earth)
        try:
            return RestSettings(**fields)
        except ValueError as err:
            raise ParameterError(f'rest learning parameters: {err}') from None

    def _on_set_parameters(self, params: Sequence[Parameter]) -> SetParametersResult:
        changes = {p.name: p for p in params}
        if 'require_frame_id_match' in changes:
            self._require_frame_match = bool(changes['require_frame_id_match'].value)
        if 'inflate_covariance' in changes:
            self._inflate_covariance = bool(changes['inflate_covariance'].value)
        rebuild = set(changes) & ({'coefficients_file'} | set(FILTER_PARAMETERS))
        guard_change = set(changes) & set(GUARD_PARAMETERS)
        if not self.configured:  # lifecycle node not configured: configure checks them
            return SetParametersResult(successful=True)
        if not (rebuild or guard_change):
            return SetParametersResult(successful=True)
        try:
            config = self._build_config(changes)
        except (CoefficientsError, ValueError, TypeError) as err:
            return SetParametersResult(successful=False, reason=str(err))
        if rebuild:  # the learned bias belongs to the old coefficients: keep it in the file
            self.save_learned_bias('reconfigure')
        self.config = config
        if rebuild:
            counters = self.compensator.status.counters
            self.compensator = Compensator(
                config.coefficients.model, config.settings, config.guard, config.rest
            )
            self.compensator.status.counters = counters
            self._load_learned_bias()
            self.reconfigurations += 1
            self._log_config(f'reconfigured ({", ".join(sorted(rebuild))})')
        else:
            self.compensator.guard = config.guard
        return SetParametersResult(successful=True)

    def _log_config(self, what: str) -> None:
        cfg = self.config
        self.get_logger().info(
            f'{what}: coefficients {cfg.coefficients_file} '
            f'(frame {cfg.coefficients.frame_id or "any"}), Tdot denoise {cfg.settings.method}'
        )

    # ------------------------------------------------------------------ data
    def _unset_stamp_s(self) -> float:
        """The node clock's time, s, for a temperature whose driver left the stamp unset (0).

        (An unset gyro stamp goes to the core, which corrects it with the current correction
        and counts it.)
        """
        self.unstamped += 1
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_temperature(self, msg: Temperature) -> None:
        stamp = msg.header.stamp
        stamp_s = stamp.sec + stamp.nanosec * 1e-9 or self._unset_stamp_s()
        was_ready = self.compensator.status.estimator_ready
        if self.compensator.add_temperature(stamp_s, msg.temperature):
            self._track_warm_up(stamp_s, was_ready)

    def _track_warm_up(self, stamp_s: float, was_ready: bool) -> None:
        """INFO once when the Tdot estimator becomes ready: its Tdot terms start to apply."""
        if not self.compensator.status.estimator_ready:
            if self._warm_up_start_s is None or was_ready:
                self._warm_up_start_s = stamp_s
            return
        if not was_ready and self._warm_up_start_s is not None:
            self.get_logger().info(
                f'Tdot estimator {self.config.settings.method} warmed up after '
                f'{stamp_s - self._warm_up_start_s:.1f} s of temperature: full correction '
                'from now on (Tdot terms included)'
            )
        self._warm_up_start_s = None

    def _on_at_rest(self, msg: Bool) -> None:
        if self.configured and self.compensator.rest is not None:
            self.compensator.rest.set_external_rest(msg.data)

    def _on_imu(self, msg: Imu) -> None:
        if not self.output_enabled:  # inactive lifecycle node: no output, no gyro state
            self.imu_while_inactive += 1
            return
        stamp = msg.header.stamp
        w = msg.angular_velocity
        expected_frame = self.config.coefficients.frame_id
        if expected_frame and msg.header.frame_id != expected_frame:
            self.frame_mismatches += 1
            if self._require_frame_match:
                self._publisher.publish(msg)
                return
        compensator = self.compensator
        stamp_s = stamp.sec + stamp.nanosec * 1e-9  # 0: the core's current correction
        if compensator.rest is None:
            rate = compensator.correct_xyz(stamp_s, w.x, w.y, w.z)
        else:
            a = msg.linear_acceleration
            rate = compensator.correct_xyz(stamp_s, w.x, w.y, w.z, (a.x, a.y, a.z))
        if rate is None:  # duplicate stamp: dropped and counted
            return
        w.x, w.y, w.z = rate
        if self._inflate_covariance:
            self._inflate(msg)
        self._publisher.publish(msg)

    def _inflate(self, msg: Imu) -> None:
        cov = msg.angular_velocity_covariance
        if cov[0] < 0:  # -1: covariance unknown, leave the convention alone
            return
        fit = self.config.coefficients.fit
        for j, axis in enumerate(AXES):
            std_deg_h = float(fit.get(axis, {}).get('residual_std_deg_h', 0.0))
            cov[4 * j] += (std_deg_h * RAD_S_PER_DEG_H) ** 2

    # ------------------------------------------------------------------ console
    def _log_console(self, counters: Any, previous: Any) -> None:
        """Throttled console lines for what went wrong since the last report.

        Each kind has its own call (rclpy throttles per call site), at most one line per
        ``log_throttle_s``.
        """
        status = self.compensator.status
        log = self.get_logger()
        every = self._throttle_s
        topic = self._temp_sub.topic_name
        uncorrected = counters.imu_uncorrected - previous.imu_uncorrected
        if uncorrected and not status.has_temperature:
            log.warning(
                f'no temperature received on {topic}: gyro passed through uncorrected '
                f'({uncorrected} messages)',
                throttle_duration_sec=every,
            )
        if counters.temperature_rejected > previous.temperature_rejected:
            log.warning(
                f'non-finite temperature on {topic}: samples rejected '
                f'({counters.temperature_rejected - previous.temperature_rejected})',
                throttle_duration_sec=every,
            )
        guard = self.compensator.guard
        age_s = status.last_imu_stamp_s - status.last_temperature_stamp_s
        if counters.imu_held > previous.imu_held:
            log.warning(
                f'temperature on {topic} stale: last sample {age_s:.1f} s before the gyro '
                f'stamp (temperature_timeout_s {guard.temperature_timeout_s:g}): holding the '
                'last correction',
                throttle_duration_sec=every,
            )
        if uncorrected and status.has_temperature and status.temperature_stale:
            log.error(
                f'fallback to pass-through: temperature on {topic} stale, last sample '
                f'{age_s:.1f} s before the gyro stamp (temperature_timeout_s '
                f'{guard.temperature_timeout_s:g}, stale_policy none): gyro not corrected',
                throttle_duration_sec=every,
            )
        if self._require_frame_match and self.frame_mismatches > self._last_frame_mismatches:
            log.error(
                'fallback to pass-through: gyro frame_id differs from the calibrated '
                f'{self.config.coefficients.frame_id!r} (require_frame_id_match): '
                f'{self.frame_mismatches - self._last_frame_mismatches} messages not corrected',
                throttle_duration_sec=every,
            )
        self._last_frame_mismatches = self.frame_mismatches
        model = self.config.coefficients.model
        if counters.imu_temperature_clamped > previous.imu_temperature_clamped:
            t_range = model.temperature_range_degC
            log.warning(
                f'temperature {status.temperature_degC:.2f} degC outside the calibrated '
                f'[{t_range.low:.2f}, {t_range.high:.2f}] degC: clamped to '
                f'{status.temperature_used_degC:.2f} degC',
                throttle_duration_sec=every,
            )
        if counters.imu_tdot_clamped > previous.imu_tdot_clamped:
            log.warning(
                f'Tdot {status.tdot_degC_per_min:.3f} degC/min clamped to '
                f'{status.tdot_used_degC_per_min:.3f} degC/min ('
                + (
                    'clamp_tdot: calibrated range'
                    if guard.clamp_tdot
                    else f'tdot_limit_degC_per_min {guard.tdot_limit_degC_per_min:g}'
                )
                + ')',
                throttle_duration_sec=every,
            )

    # ------------------------------------------------------------------ diagnostics
    def publish_diagnostics(self) -> None:
        """Publish one DiagnosticArray with the compensator's health."""
        now = time.monotonic()
        elapsed = max(now - self._last_report_time, 1e-9)
        counters = self.compensator.status.counters
        previous = self._last_counters
        self._check_forced_window()  # first: the report shows the file it may write
        report = build_report(
            self.compensator.status,
            previous,
            coefficients=self.config.coefficients,
            coefficients_file=self.config.coefficients_file,
            method=self.config.settings.method,
            imu_rate_hz=(counters.imu_total - previous.imu_total) / elapsed,
            temperature_rate_hz=(counters.temperature_total - previous.temperature_total)
            / elapsed,
            frame_mismatches=self.frame_mismatches,
            unstamped=self.unstamped,
            require_frame_match=self._require_frame_match,
            rest=None if self.compensator.rest is None else self.compensator.rest.finish(),
            rest_bias_file=(
                (self.config.rest_bias_file, self._rest_bias_state)
                if self.compensator.rest is not None and self.config.rest_bias_file
                else None
            ),
        )
        self._log_console(counters, previous)
        self._last_counters = dataclasses.replace(counters)
        self._last_report_time = now
        status = DiagnosticStatus(
            level=bytes([report.level]),
            name=f'{self.get_name()}: FOG temperature compensation',
            message=report.message,
            hardware_id=self.config.coefficients.frame_id,
            values=[KeyValue(key=k, value=v) for k, v in report.values],
        )
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self._diag_pub.publish(array)


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


_KINDS = {
    _T.BOOL: 'bool',
    _T.INTEGER: 'integer',
    _T.DOUBLE: 'double',
    _T.STRING: 'string',
}


def _bad_value_text(node: Node, name: str, value: Any, descriptor: ParameterDescriptor) -> str:
    """One line: the parameter, the type and range it takes, and the value it was given."""
    if isinstance(value, Parameter.Type):
        ptype = value
    else:
        ptype = Parameter.Type.from_parameter_value(value)
    low = high = None
    if descriptor.floating_point_range:
        low = descriptor.floating_point_range[0].from_value
        high = descriptor.floating_point_range[0].to_value
    elif descriptor.integer_range:
        low = descriptor.integer_range[0].from_value
        high = descriptor.integer_range[0].to_value
    expected = expected_text(_KINDS.get(ptype, ptype.name.lower()), low, high)
    given = getattr(node, '_parameter_overrides', {}).get(name)
    if given is None:
        return f'parameter {name}: expected {expected}'
    given_kind = _KINDS.get(given.type_, given.type_.name.lower())
    hint = ''
    if ptype == _T.DOUBLE and given.type_ == _T.INTEGER:
        hint = f' (write {given.value}.0 for a double)'
    return f'parameter {name}: expected {expected}, got {given.value!r} ({given_kind}){hint}'


def make_executor(node: Node) -> Executor:
    """The executor the node's ``executor`` parameter names (see its description)."""
    name = node.get_parameter('executor').value
    if name not in ('auto', 'events', 'single'):
        raise ValueError(f"parameter executor: {name!r} is not one of 'auto', 'events', 'single'")
    if name in ('auto', 'events'):
        try:
            from rclpy.experimental import EventsExecutor  # Jazzy and later
        except ImportError:
            if name == 'events':
                node.get_logger().warning(
                    'executor events: rclpy.experimental.EventsExecutor is not available in '
                    'this ROS distribution; using the SingleThreadedExecutor'
                )
        else:
            return EventsExecutor(context=node.context)
    return SingleThreadedExecutor(context=node.context)


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of ``ros2 run fog_temp_comp compensator``."""
    return run(CompensatorNode, args)


def run(node_class: Callable[..., Node], args: Sequence[str] | None = None) -> int:
    """Init rclpy, spin one ``node_class(params_file_paths=...)`` until shutdown; exit code."""
    argv = list(sys.argv if args is None else args)
    try:  # before rcl, which logs its own error and raises on a file it cannot parse
        files = params_files(argv)
        for path in files:
            read_params_file(path)
        rclpy.init(args=argv)
    except ParameterError as err:
        print(f'ERROR: {err}', file=sys.stderr)
        return 1
    except RCLError as err:
        print(f'ERROR: {str(err).splitlines()[0]}', file=sys.stderr)
        return 1
    node = None
    executor = None
    try:
        node = node_class(params_file_paths=files)
        executor = make_executor(node)
        executor.add_node(node)
        if isinstance(executor, SingleThreadedExecutor):
            executor.spin()
        else:  # EventsExecutor.spin() of the Jazzy wheels runs no callback; spin_once does
            while node.context.ok():
                executor.spin_once(timeout_sec=0.5)
    except (CoefficientsError, ValueError) as err:
        print(f'ERROR: {err}', file=sys.stderr)
        return 1
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if executor is not None:
            executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
