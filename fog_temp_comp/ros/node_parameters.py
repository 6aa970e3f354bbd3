"""The compensator node's ROS parameters: their tables, declaring them, and the Config they make.

The tables name each parameter with its default (or type) and description: the Tdot filter
(unset = as in the coefficients file), the input guards, and bias learning at rest. Units are in
the names and descriptions (s, degC, degC/min, deg/h, m/s^2). :class:`ParametersMixin` declares
them on an rclpy node (a bad override is one ``ERROR:`` line) and builds the :class:`Config` the
:class:`~fog_temp_comp.core.compensator.Compensator` is built from.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.exceptions import (
    InvalidParameterTypeException,
    InvalidParameterValueException,
    ParameterUninitializedException,
)
from rclpy.node import Node
from rclpy.parameter import Parameter

from fog_temp_comp.core.coefficients import Coefficients, CoefficientsError, load
from fog_temp_comp.core.compensator import (
    STALE_POLICIES,
    STALE_SAMPLE_INTERVALS,
    Compensator,
    GuardSettings,
)
from fog_temp_comp.core.denoise import (
    BOUNDARY_MODES,
    METHODS,
    THRESHOLD_MODES,
    THRESHOLD_RULES,
    DenoiseSettings,
)
from fog_temp_comp.core.earth import earth_rate_body_deg_h, parse_orientation
from fog_temp_comp.core.rest import REST_SOURCES, RestSettings
from fog_temp_comp.ros.params import (
    ParameterError,
    expected_text,
    read_params_file,
    sections_warning,
)
from fog_temp_comp.ros.temperature_input import DEFAULT_FIELD, DEFAULT_TYPE

__all__ = [
    'FILTER_PARAMETERS',
    'GUARD_PARAMETERS',
    'REST_EARTH_PARAMETERS',
    'REST_PARAMETERS',
    'Config',
    'ParametersMixin',
    'resolve_path',
]

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
    'sensor_lag_s': (
        'sensor_lag_s',
        _T.DOUBLE,
        'lag (s) of the temperature sensor behind the coil, modelled by the Kalman filter, '
        'kalman; 0 = none',
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
    'tdot_wiener_window_s': (
        'tdot_wiener_window_s',
        _T.DOUBLE,
        'window (s) of the Tdot Wiener gain: Tdot times the share of its recent power that is '
        'not estimator noise (quiet soaks), kalman; 0 = off',
    ),
    'kalman_repeat_rate_degC_per_min': (
        'kalman_repeat_rate_degC_per_min',
        _T.DOUBLE,
        'slowest ramp (degC/min): a reading on one step for longer than such a ramp takes to '
        'cross it weighs less (repeats share one quantization error), kalman; 0 = off',
    ),
    'kalman_hysteresis_quanta': (
        'kalman_hysteresis_quanta',
        _T.DOUBLE,
        'hysteresis on the readings, in quantization steps (0..1): a sensor toggling between '
        'two steps reads as the boundary between them, kalman; 0 = off',
    ),
    'kalman_quantized_noise_degC': (
        'kalman_quantized_noise_degC',
        _T.DOUBLE,
        'white noise (degC) of the temperature sensor before its quantization: the filter uses '
        'the exact likelihood of each quantized reading, kalman; 0 = off (calibrate fits it)',
    ),
    'temperature_period_s': (
        'temperature_period_s',
        _T.DOUBLE,
        "the temperature sensor's interval between readings (s): temperature is stale only "
        f'after {STALE_SAMPLE_INTERVALS:g} of them (and temperature_timeout_s); 0 = unknown '
        '(calibrate measures it)',
    ),
    'temperature_hold_s': (
        'temperature_hold_s',
        _T.DOUBLE,
        'for a temperature published only when it changes, how long (s) after each reading its '
        'value is put back at temperature_period_s; 0 = published at the sensor rate '
        '(calibrate detects it)',
    ),
    'temperature_spread_s': (
        'temperature_spread_s',
        _T.DOUBLE,
        "for a driver that delivers the readings in polls stamped on receipt, the sensor's "
        "interval (s) at which each poll's readings are stamped back from its first; 0 = "
        'stamped as taken (calibrate detects it)',
    ),
}
_GUARD_DEFAULTS = GuardSettings()
#: input guards: name -> (default, text)
GUARD_PARAMETERS: dict[str, tuple[Any, str]] = {
    'temperature_timeout_s': (
        _GUARD_DEFAULTS.temperature_timeout_s,
        'temperature older than this (s) relative to a gyro stamp is stale (or than '
        f'{STALE_SAMPLE_INTERVALS:g} intervals of a slower sensor: temperature_period_s)',
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
        'two stamps in a row this far (s) behind the one before reset the filter (bag loop, '
        'sim reset); one alone is out of order',
    ),
    'max_temperature_step_degC': (
        _GUARD_DEFAULTS.max_temperature_step_degC,
        'temperature jump (degC) beyond which a sample is a glitch unless confirmed',
    ),
    'max_temperature_rate_degC_per_min': (
        _GUARD_DEFAULTS.max_temperature_rate_degC_per_min,
        'plausible temperature rate (degC/min) added to the glitch threshold',
    ),
    'temperature_fault_margin_degC': (
        _GUARD_DEFAULTS.temperature_fault_margin_degC,
        'a temperature further than this (degC) outside the calibrated range is a sensor fault '
        '(an error code such as -127): rejected, the gyro gets stale_policy (1e6: off)',
    ),
    'temperature_bridge_s': (
        _GUARD_DEFAULTS.temperature_bridge_s,
        'a gap between temperature readings up to this long (s) is bridged by the Kalman '
        "filter's prediction (Tdot terms go on); a longer one restarts it (0: every gap)",
    ),
    'adopt_delivery': (
        _GUARD_DEFAULTS.adopt_delivery,
        'where the coefficients say nothing of it (temperature_hold_s and temperature_spread_s '
        '0) and the readings look published only on change or delivered in polls, take their '
        "timing from them rather than go stale at each silence (false: keep the file's)",
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
    except OSError:  # ament_index raises it when AMENT_PREFIX_PATH is unset or empty
        raise CoefficientsError(
            f'coefficients_file {path}: AMENT_PREFIX_PATH is not set, so package:// paths '
            'cannot be resolved: source the workspace (. install/setup.sh) or give a file path'
        ) from None
    return os.path.join(share, relative)


if TYPE_CHECKING:  # the mixins are always combined with a Node: type them as one
    _NodeBase = Node
else:
    _NodeBase = object


class ParametersMixin(_NodeBase):
    """Declares the node's parameters and builds its :class:`Config`; holds the compensator.

    A mixin for an rclpy ``Node`` (or ``LifecycleNode``), the base of the other mixins of
    :class:`~fog_temp_comp.ros.compensator_shell.CompensatorShell`.
    """

    #: both None only while a lifecycle node is unconfigured, when none of the callbacks
    #: below runs (no subscription, no timer); typed for the configured state they run in
    config: Config
    compensator: Compensator

    @property
    def configured(self) -> bool:
        """Whether the compensator exists (always for the plain node)."""
        return getattr(self, 'compensator', None) is not None

    def _forget_compensator(self) -> None:
        """Unconfigured: no coefficients, no compensator."""
        self.config = None  # type: ignore[assignment]
        self.compensator = None  # type: ignore[assignment]

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
            'time_source',
            'header',
            ParameterDescriptor(
                description="time gyro and temperature by their 'header' stamps, or by the "
                "node clock on arrival ('receive': drivers stamping with two clocks)",
                read_only=True,
                additional_constraints="one of 'header', 'receive'",
            ),
        )
        self._declare_temperature_input()
        self._declare(
            'executor',
            'auto',
            ParameterDescriptor(
                description="executor of `ros2 run`: 'events' (rclpy.experimental."
                "EventsExecutor, in Jazzy's rclpy, not Humble's: keeps up with a 2 kHz gyro), "
                "'single' (SingleThreadedExecutor), or 'auto' (events where rclpy has it, "
                "else single, said at INFO); 'events' without it falls back to single with a "
                'warning',
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

    def _declare_temperature_input(self) -> None:
        """The temperature input: type, field and frame_id (of several sensors on one topic)."""
        self._declare(
            'temperature_type',
            DEFAULT_TYPE,
            ParameterDescriptor(
                description="message type of imu/temperature, 'pkg/msg/Type': another type "
                "carries the temperature in 'temperature_field' (a driver's status message, "
                'std_msgs/msg/Float64; one without a header is timed on arrival)',
                read_only=True,
            ),
        )
        self._declare(
            'temperature_field',
            DEFAULT_FIELD,
            ParameterDescriptor(
                description="field of 'temperature_type' holding the temperature in degC, "
                "'a.b.c' (as calibrate --temp-field)",
                read_only=True,
            ),
        )
        self._declare(
            'temperature_frame_id',
            '',
            ParameterDescriptor(
                description="of a temperature topic that carries several sensors' readings "
                "(told by header.frame_id), keep this one's; '' keeps the coefficients file's "
                'temperature_frame_id (the one calibrate kept), else the first seen',
                read_only=True,
            ),
        )

    def _declare_table_parameters(self) -> None:
        """The Tdot filter, guard and rest-learning parameters, from their tables."""
        for name, (_, ptype, text) in FILTER_PARAMETERS.items():
            descriptor = ParameterDescriptor(
                description=text + "; unset: the coefficients file's value, set at load; "
                'changing it restarts the Tdot filter'
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
                low = 0.0 if name == 'temperature_bridge_s' else 0.001  # 0: never bridged
                descriptor.floating_point_range = [
                    FloatingPointRange(from_value=low, to_value=1e6, step=0.0)
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
        from_file: set[str] = getattr(self, '_filter_from_file', set()) - set(changes)
        for name, (field, _, _) in FILTER_PARAMETERS.items():
            value = None if name in from_file else self._value(name, changes)
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
