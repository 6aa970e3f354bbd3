"""The ROS glue shared by the ``compensator`` node and its lifecycle twin (CompensatorShell).

Subscriptions and publishers around one :class:`~fog_temp_comp.core.compensator.Compensator`:
messages become floats (stamps in s, rates in rad/s, temperature in degC) and the corrected rates
go back into the Imu; parameter changes rebuild the compensator (new coefficients with the same
filter settings keep its Tdot filter); ``/diagnostics`` is published on a timer. Parameters,
the learned-bias file and the console lines are its mixins'
(:mod:`~fog_temp_comp.ros.node_parameters`, :mod:`~fog_temp_comp.ros.bias_learning`,
:mod:`~fog_temp_comp.ros.console_log`).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from copy import copy
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import SetParametersResult
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.qos import qos_profile_sensor_data
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import Imu
from std_msgs.msg import Bool
from std_srvs.srv import Trigger

from fog_temp_comp.core.coefficients import Coefficients, CoefficientsError
from fog_temp_comp.core.compensator import Compensator
from fog_temp_comp.core.frame_lock import FrameLock
from fog_temp_comp.core.stamp_offset import (
    GROSS_CLOCK_MISMATCH_S,
    TIME_SOURCES,
    ArrivalOffsets,
    header_clock_offset_s,
)
from fog_temp_comp.core.units import AXES, RAD_S_PER_DEG_H
from fog_temp_comp.ros.bias_learning import BiasLearningMixin
from fog_temp_comp.ros.console_log import ConsoleLogMixin
from fog_temp_comp.ros.diagnostics import build_report, reading_model
from fog_temp_comp.ros.input_types import TypeMismatch, type_mismatches
from fog_temp_comp.ros.node_parameters import FILTER_PARAMETERS, GUARD_PARAMETERS, Config
from fog_temp_comp.ros.params import ParameterError, params_files, unknown_warnings
from fog_temp_comp.ros.qos_profiles import IMU_INPUT_DEPTH, IMU_INPUT_QOS, OUTPUT_QOS
from fog_temp_comp.ros.rclpy_compat import RCLError
from fog_temp_comp.ros.spin import EXECUTORS
from fog_temp_comp.ros.temperature_input import (
    DEFAULT_FIELD,
    DEFAULT_TYPE,
    TemperatureInput,
    temperature_input,
)

__all__ = ['IMU_INPUT_DEPTH', 'IMU_INPUT_QOS', 'OUTPUT_QOS', 'CompensatorShell']

#: other temperature frame_ids whose latest reading is kept for a reload (bounded memory)
MAX_OTHER_FRAMES = 16


class CompensatorShell(BiasLearningMixin, ConsoleLogMixin):
    """The ROS glue shared by :class:`CompensatorNode` and the lifecycle node.

    A mixin for an rclpy ``Node`` (or ``LifecycleNode``): parameters, the subscriptions and
    publishers around one :class:`Compensator`, console lines and diagnostics. The two nodes
    differ only in when they call :meth:`_setup_parameters`, :meth:`_configure`,
    :meth:`_create_io` and :meth:`_destroy_io`.
    """

    def _setup_parameters(self, params_file_paths: Sequence[str], cli_args: Any) -> None:
        """Declare and check the parameters (raises :class:`ParameterError` on a bad one)."""
        self._check_params_files([*params_file_paths, *params_files(cli_args)])
        self._declare_parameters()
        #: filter parameters not set by the user: they hold the coefficients file's values
        self._filter_from_file = {n for n in FILTER_PARAMETERS if self._value(n, {}) is None}
        self._showing_file_values = False
        executor = self.get_parameter('executor').value
        if executor not in EXECUTORS:
            raise ParameterError(
                f'parameter executor: expected one of {EXECUTORS}, got {executor!r}'
            )
        time_source = self.get_parameter('time_source').value
        if time_source not in TIME_SOURCES:
            raise ParameterError(
                f'parameter time_source: expected one of {TIME_SOURCES}, got {time_source!r}'
            )
        #: messages timed by the node clock on arrival, not their header stamps
        self._by_receive = time_source == 'receive'
        #: sensor_msgs/Temperature, or a field of another message type
        self._temperature = temperature_input(
            self.get_parameter('temperature_type').value,
            self.get_parameter('temperature_field').value,
        )
        for line in unknown_warnings(self._given_parameters(), self._parameters):
            self.get_logger().warning(line)
        self._forget_compensator()
        self.reconfigurations = 0
        self.frame_mismatches = 0
        #: messages with an unset (0) header stamp, timed by the node clock instead
        self.unstamped = 0
        #: gyro messages of a gyro never stamped (0), timed by the node clock on arrival
        self.gyro_unstamped = 0
        self._gyro_stamped = False  # a gyro message with a header stamp came
        #: the last stamped temperature's clock minus the node clock, s (0 within 5 s)
        self._header_clock_s = 0.0
        #: temperature minus gyro header clock (s) that made the node time both on arrival
        #: (:meth:`_time_on_arrival`); nan while it times by header stamp as asked
        self.clocks_apart_s = math.nan
        self._require_frame_match = bool(self.get_parameter('require_frame_id_match').value)
        self._inflate_covariance = bool(self.get_parameter('inflate_covariance').value)
        self._throttle_s = float(self.get_parameter('log_throttle_s').value)
        self._warm_up_start_s: float | None = None
        self._last_frame_mismatches = 0
        #: gyro messages are corrected and published only while this is set (lifecycle: active)
        self.output_enabled = True
        #: gyro messages ignored while output_enabled was off
        self.imu_while_inactive = 0
        #: gyro messages received (any frame_id, active or not): ``imu_rate_hz``
        self.imu_received = 0
        #: Imu messages handed to the output's publisher (corrected, or passed through as they
        #: came; tests wait for exactly these)
        self.imu_published = 0
        self.add_on_set_parameters_callback(self._on_set_parameters)

    def _configure(self) -> None:
        """Load and validate the coefficients, build the compensator (raises on bad ones)."""
        resolve = getattr(self, 'resolve_topic_name', None)  # guarded: not in every rclpy
        if resolve is not None and resolve('imu/data') == resolve('imu/data_raw'):
            raise ValueError(
                f'the output topic imu/data is remapped onto the gyro input '
                f'{resolve("imu/data_raw")}: the node '
                'would correct its own output again and again; remap one of them elsewhere'
            )
        self.config = self._build_config({})
        self._temperature = self._fitted_temperature_input(self.config.coefficients)
        fitted = self.config.coefficients.temperature_topic
        if fitted and resolve is not None and resolve('imu/temperature') != fitted:
            self.get_logger().warning(
                f'the coefficients were fitted on the temperature topic {fitted}, this node reads '
                f'{resolve("imu/temperature")}: remap imu/temperature:={fitted}'
            )
        self.compensator = Compensator(
            self.config.coefficients.model,
            self.config.settings,
            self.config.guard,
            self.config.rest,
        )
        self._warm_up_start_s = None
        self._show_filter_in_effect()
        #: which frame_id's temperatures are kept (a topic with several sensors' readings)
        self.temperature_frames = FrameLock(
            self.get_parameter('temperature_frame_id').value
            or self.config.coefficients.temperature_frame_id
        )
        self._frames_logged = False
        #: the latest reading (stamp s, degC) of each frame_id not kept, for a reload to it
        self._other_frames_latest: dict[str, tuple[float, float]] = {}
        #: temperature stamps against the gyro's latest on arrival: two clocks, seen live
        self._arrival = ArrivalOffsets()
        self._imu_total_at_temperature = 0
        self._load_learned_bias()

    def _fitted_temperature_input(
        self, coeffs: Coefficients, *, log: bool = True
    ) -> TemperatureInput:
        """The temperature input: the parameters', or else the one the coefficients were fitted on.

        Where ``temperature_type`` and ``temperature_field`` are left at their defaults and
        the coefficients were fitted on a field of another message type (a bare
        ``std_msgs/Float64``: their ``temperature_type``), the node subscribes to that (an
        info line says so). Raises :class:`ParameterError` where that type is not here.
        """
        asked = (
            self.get_parameter('temperature_type').value,
            self.get_parameter('temperature_field').value,
        )
        if not coeffs.temperature_type or asked != (DEFAULT_TYPE, DEFAULT_FIELD):
            return temperature_input(*asked)
        try:
            chosen = temperature_input(coeffs.temperature_type, coeffs.temperature_field)
        except ParameterError as err:  # a driver's type whose workspace is not sourced
            reason = str(err).removeprefix('parameter ')
            raise ParameterError(
                f"the coefficients' {reason} (or set parameters temperature_type and "
                'temperature_field)'
            ) from err
        if log:
            self.get_logger().info(
                f'reading the temperature (degC) from field {coeffs.temperature_field} of '
                f'{coeffs.temperature_type}, as the coefficients were fitted (parameters '
                'temperature_type and temperature_field choose another)'
            )
        return chosen

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
        # copies: rclpy applies a qos_overrides parameter to the profile it is given, in place,
        # which would carry one node's override into every later node of the process
        self._publisher = self._create_output(
            Imu, 'imu/data', copy(OUTPUT_QOS), qos_overriding_options=qos_options
        )
        self._imu_sub = self.create_subscription(
            Imu,
            'imu/data_raw',
            self._on_imu,
            copy(IMU_INPUT_QOS),
            qos_overriding_options=qos_options,
        )
        self._temp_sub = self.create_subscription(
            self._temperature.msg_type,
            'imu/temperature',
            self._on_temperature,
            copy(qos_profile_sensor_data),
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
        self._last_received = (self.imu_received, self.imu_while_inactive)
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

    # ------------------------------------------------------------------ parameter changes
    def _show_filter_in_effect(self) -> None:
        """Give each filter parameter the user left unset the coefficients file's value.

        ``ros2 param get`` and ``dump`` then show the filter in effect (and rclpy answers a
        GetParameters request naming one parameter without a value with no values at all).
        Such values stay the file's: the next coefficients file replaces them.
        """
        kinds = {Parameter.Type.DOUBLE: float, Parameter.Type.INTEGER: int}
        shown = []
        for name in sorted(self._filter_from_file):
            field, ptype, _ = FILTER_PARAMETERS[name]
            value = kinds.get(ptype, str)(getattr(self.config.settings, field))
            if not (isinstance(value, float) and not math.isfinite(value)):
                shown.append(Parameter(name, ptype, value))
        self._showing_file_values = True
        try:  # each set alone: one outside its parameter's range is left unset
            results = self.set_parameters(shown)
        finally:
            self._showing_file_values = False
        for param, result in zip(shown, results, strict=True):
            if not result.successful:
                self.get_logger().debug(
                    f'{param.name}: {param.value!r} not shown: {result.reason}'
                )

    def _show_filter_in_effect_soon(self) -> None:
        """:meth:`_show_filter_in_effect` once the parameter change under way is done."""

        def once() -> None:
            self.destroy_timer(timer)
            if self.configured:
                self._show_filter_in_effect()

        timer = self.create_timer(0.0, once)

    def _on_set_parameters(self, params: Sequence[Parameter]) -> SetParametersResult:
        """Check the whole change first: a refused one changes nothing (atomic requests too)."""
        if self._showing_file_values:  # the coefficients file's own values, in effect already
            return SetParametersResult(successful=True)
        changes = {p.name: p for p in params}
        rebuild = set(changes) & ({'coefficients_file'} | set(FILTER_PARAMETERS))
        if not self.configured:  # lifecycle node not configured: configure checks them
            self._filter_from_file -= set(changes)
        elif rebuild or set(changes) & set(GUARD_PARAMETERS):
            try:
                config = self._build_config(changes)
                temperature = self._reloaded_temperature_input(config.coefficients)
            except (CoefficientsError, ValueError, TypeError) as err:
                return SetParametersResult(successful=False, reason=str(err))
            self._apply_config(config, temperature, rebuild, set(changes))
        if 'require_frame_id_match' in changes:
            self._require_frame_match = bool(changes['require_frame_id_match'].value)
        if 'inflate_covariance' in changes:
            self._inflate_covariance = bool(changes['inflate_covariance'].value)
        return SetParametersResult(successful=True)

    def _apply_config(
        self, config: Config, temperature: TemperatureInput, rebuild: set[str], changed: set[str]
    ) -> None:
        """Put a checked config in effect: new guards, or (``rebuild``) a new compensator."""
        if rebuild:  # the learned bias belongs to the old coefficients: keep it in the file
            self.save_learned_bias('reconfigure')
            self._filter_from_file -= changed
            self._show_filter_in_effect_soon()
        previous, self.config = self.config, config
        self._temperature = temperature
        if not rebuild:
            self.compensator.guard = config.guard
            return
        kept = self.temperature_frames.kept
        moved = self._follow_temperature_frame(config.coefficients)
        if previous.settings == config.settings and not (moved or self.compensator.rest):
            self.compensator.use_model(config.coefficients.model)  # the Tdot filter goes on
            self.compensator.guard = config.guard
            self._done_reconfiguring(rebuild)
            return
        counters = self.compensator.status.counters
        last_reading = self.compensator.last_reading
        if moved:
            # another sensor: its latest reading where one came (else its next starts it)
            if kept is not None and last_reading is not None:
                self._other_frames_latest[kept] = last_reading
            new_frame = config.coefficients.temperature_frame_id
            last_reading = self._other_frames_latest.pop(new_frame, None)
        self.compensator = Compensator(
            config.coefficients.model, config.settings, config.guard, config.rest
        )
        if last_reading is not None:  # the gyro goes on corrected (or held), not waiting
            self.compensator.start_from(*last_reading)
        self.compensator.status.counters = counters
        self._done_reconfiguring(rebuild)

    def _done_reconfiguring(self, rebuild: set[str]) -> None:
        self._load_learned_bias()
        self.reconfigurations += 1
        self._log_config(f'reconfigured ({", ".join(sorted(rebuild))})')

    def _follow_temperature_frame(self, coeffs: Coefficients) -> bool:
        """Keep new coefficients' temperature sensor (``temperature_frame_id`` parameter '').

        The parameter, where set, stays; coefficients naming no frame_id keep the sensor kept.
        Returns whether the readings now kept are another sensor's.
        """
        wanted = coeffs.temperature_frame_id
        frames = self.temperature_frames
        if self.get_parameter('temperature_frame_id').value or wanted in ('', frames.preferred):
            return False
        self.temperature_frames = FrameLock(wanted)
        self._frames_logged = False
        moved = frames.kept != wanted
        if not moved:
            self.temperature_frames.kept = wanted
        self.get_logger().info(
            f"the temperature of frame_id {wanted} is kept from now on (the new coefficients' "
            f'temperature_frame_id; was {frames.kept or "none yet"})'
        )
        return moved

    def _reloaded_temperature_input(self, coeffs: Coefficients) -> TemperatureInput:
        """The temperature input of new coefficients; ValueError where its type changes.

        The subscription's type is fixed while the node runs: such coefficients need a restart.
        """
        reloaded = self._fitted_temperature_input(coeffs, log=False)
        wanted, have = reloaded.msg_type, self._temperature.msg_type
        if wanted is not have:
            raise ValueError(
                f'these coefficients read the temperature from a {wanted.__module__}.'
                f'{wanted.__name__}, the node subscribes to {have.__module__}.{have.__name__}: '
                'restart the node with them'
            )
        return reloaded

    # ------------------------------------------------------------------ data
    def _unset_stamp_s(self) -> float:
        """The node clock's time, s, for a temperature whose driver left the stamp unset (0).

        Moved onto the clock of the temperature's other stamps where that runs more than 5 s
        from the node's (a device's clock since power-on); so is a gyro never stamped.
        """
        self.unstamped += 1
        return self._now_s() + self._header_clock_s

    def _now_s(self) -> float:
        """The node clock's time, s."""
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_temperature(self, msg: Any) -> None:
        temperature = self._temperature
        if temperature.stamped and not self.temperature_frames.keep(msg.header.frame_id):
            self._note_other_frame(msg)
            if self.temperature_frames.kept is not None and not self._frames_logged:
                self._log_other_frames()
            return
        if self._by_receive:
            stamp_s = self._now_s()
        elif temperature.stamped:
            stamp = msg.header.stamp
            stamp_s = stamp.sec + stamp.nanosec * 1e-9
            if stamp_s:
                self._header_clock_s = header_clock_offset_s(stamp_s - self._now_s())
            else:
                stamp_s = self._unset_stamp_s()
        else:  # a message without a header (std_msgs/Float64): timed on arrival
            stamp_s = self._unset_stamp_s()
        status = self.compensator.status
        was_ready = status.estimator_ready
        if self.compensator.add_temperature(stamp_s, temperature.degC(msg)):
            self._track_warm_up(stamp_s, was_ready)
        # the clocks compared on every reading, taken or not (a clock stepped back is refused)
        imu_total = status.counters.imu_total
        if imu_total > self._imu_total_at_temperature:  # the gyro flows: compare clocks
            self._arrival.add(stamp_s, status.last_imu_stamp_s)
            arrival = self._arrival
            if arrival.two_clocks and (
                abs(arrival.offset_s) > GROSS_CLOCK_MISMATCH_S
                or arrival.offset_s < -self.compensator.stale_after_s
            ):
                self._time_on_arrival()
        self._imu_total_at_temperature = imu_total

    def _note_other_frame(self, msg: Any) -> None:
        """Keep another sensor's latest reading: a reload that moves to it starts from it."""
        frame_id, latest = msg.header.frame_id, self._other_frames_latest
        if frame_id not in latest and len(latest) >= MAX_OTHER_FRAMES:
            return
        stamp = msg.header.stamp
        stamp_s = self._now_s() if self._by_receive else stamp.sec + stamp.nanosec * 1e-9
        value = self._temperature.degC(msg)
        if stamp_s > 0.0 and math.isfinite(value):
            latest[frame_id] = (stamp_s, value)

    def _time_on_arrival(self) -> None:
        """Time gyro and temperature by the node clock: their header clocks are too far apart.

        Hours apart (a sensor clock since power-on against the computer's) no temperature
        pairs with a gyro sample; behind the gyro by more than the stale time (GPS against UTC,
        a clock stepped back) every reading is stale and the correction held as long as it
        lasts. The estimate starts again from the last reading, now (not bridged across clocks).
        """
        self.clocks_apart_s = self._arrival.offset_s
        self._by_receive = True
        self._arrival.reset()
        reading = self.compensator.last_reading
        self.compensator.reset()
        if reading is not None:  # the gyro goes on corrected, not waiting
            self.compensator.start_from(self._now_s(), reading[1])
        self._log_time_on_arrival(self.clocks_apart_s, self.compensator.stale_after_s)

    def _on_at_rest(self, msg: Bool) -> None:
        if self.configured and self.compensator.rest is not None:
            self.compensator.rest.set_external_rest(msg.data)

    def _on_imu(self, msg: Imu) -> None:
        self.imu_received += 1
        if not self.output_enabled:  # inactive lifecycle node: no output, no gyro state
            self.imu_while_inactive += 1
            return
        stamp = msg.header.stamp
        w = msg.angular_velocity
        expected_frame = self.config.coefficients.frame_id
        if expected_frame and msg.header.frame_id != expected_frame:
            self.frame_mismatches += 1
            if self._require_frame_match:
                self._send(self._publisher, msg)
                self.imu_published += 1
                return
        compensator = self.compensator
        # a stamp of 0 gets the current correction; a gyro never stamped is timed on arrival
        stamp_s = self._now_s() if self._by_receive else stamp.sec + stamp.nanosec * 1e-9
        if not self._gyro_stamped:
            self._gyro_stamped = stamp_s != 0.0
            if not stamp_s:
                self.gyro_unstamped += 1
                stamp_s = self._now_s() + self._header_clock_s
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
        self._send(self._publisher, msg)
        self.imu_published += 1

    def _inflate(self, msg: Imu) -> None:
        cov = msg.angular_velocity_covariance
        if cov[0] < 0:  # -1: covariance unknown, leave the convention alone
            return
        fit = self.config.coefficients.fit
        for j, axis in enumerate(AXES):
            std_deg_h = float(fit.get(axis, {}).get('residual_std_deg_h', 0.0))
            cov[4 * j] += (std_deg_h * RAD_S_PER_DEG_H) ** 2

    # ------------------------------------------------------------------ diagnostics
    def publish_diagnostics(self) -> None:
        """Publish one DiagnosticArray with the compensator's health."""
        now = time.monotonic()
        elapsed = max(now - self._last_report_time, 1e-9)
        counters = self.compensator.status.counters
        previous = self._last_counters
        self._check_forced_window()  # first: the report shows the file it may write
        received = self.imu_received - self._last_received[0]
        report = build_report(
            self.compensator.status,
            previous,
            coefficients=self.config.coefficients,
            coefficients_file=self.config.coefficients_file,
            method=self.config.settings.method,
            reading_model=reading_model(self.config.settings),
            imu_rate_hz=received / elapsed,
            gyro_stopped=not received and self.imu_received > 0,
            inactive=(
                None
                if self.output_enabled
                else (self.imu_while_inactive, self.imu_while_inactive - self._last_received[1])
            ),
            temperature_rate_hz=(counters.temperature_total - previous.temperature_total)
            / elapsed,
            stale_after_s=self.compensator.stale_after_s,
            frame_mismatches=(
                self.frame_mismatches,
                self.frame_mismatches - self._last_frame_mismatches,
            ),
            unstamped=(self.unstamped, self.gyro_unstamped),
            temperature_stamp_offset_s=self._arrival.offset_s,
            two_clocks=self._arrival.two_clocks,
            clocks_apart_s=self.clocks_apart_s,
            require_frame_match=self._require_frame_match,
            frames=self.temperature_frames,
            plausible_degC=self.compensator.plausible_temperature_degC,
            type_mismatches=self._type_mismatches(counters),
            untold_delivery=self.compensator.untold_delivery
            if self.compensator.status.temperature_stale
            else '',
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
        self._last_received = (self.imu_received, self.imu_while_inactive)
        status = DiagnosticStatus(
            level=bytes([report.level]),
            name=f'{self.get_fully_qualified_name().lstrip("/")}: FOG temperature compensation',
            message=report.message,
            hardware_id=self.config.coefficients.frame_id,
            values=[KeyValue(key=k, value=v) for k, v in report.values],
        )
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self._send(self._diag_pub, array)

    def _type_mismatches(self, counters: Any) -> list[TypeMismatch]:
        """The inputs that received nothing yet and are published only as other types.

        Asked of the graph while an input is silent; each found is logged (throttled).
        """
        silent = []
        if not self.imu_received:
            silent.append((self._imu_sub.topic_name, 'sensor_msgs/msg/Imu'))
        if not counters.temperature_total:
            silent.append((self._temp_sub.topic_name, self._temperature.type_name))
        found = type_mismatches(self, silent) if silent else []
        for mismatch in found:
            self.get_logger().error(mismatch.text(), throttle_duration_sec=self._throttle_s)
        return found

    def _send(self, publisher: Publisher, msg: Any) -> None:
        """Publish ``msg``; dropped without a word once rclpy is shutting down.

        A SIGINT or SIGTERM invalidates the context while a callback may still be running:
        its publish would raise, and the executor would print the traceback and exit with 1.
        """
        try:
            publisher.publish(msg)
        except RCLError:
            if self.context.ok():
                raise
