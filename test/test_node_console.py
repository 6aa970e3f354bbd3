"""What a ROS user reads on the console: one throttled line per kind of trouble.

rclpy logs through rcutils, which writes to the process's stderr (file descriptor 2), so
``capfd`` sees exactly what ``ros2 run`` prints. Each case runs the real node in an in-process
executor, makes the trouble happen three times and checks: one line the first time, none while
throttled (``log_throttle_s``), one again once the interval is over.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
from rclpy.parameter import Parameter
from rosharness import Harness

from fog_temp_comp.core.coefficients import Coefficients, save
from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS, DenoiseSettings
from fog_temp_comp.ros.node import CompensatorNode

from simdata import EXAMPLE_MODEL

T0 = 1_700_000_000.0
RATE = np.array([1e-4, -2e-4, 3e-4])  # rad/s
THROTTLE_S = 1.0
LINE = re.compile(r'^\[(DEBUG|INFO|WARN|ERROR|FATAL)\] \[[0-9.]+\] \[([^\]]+)\]: (.*)$')


def coefficients(denoise: DenoiseSettings) -> Coefficients:
    return Coefficients(model=EXAMPLE_MODEL, denoise=denoise, frame_id='imu_link')


def start(context: object, tmp_path: Path, denoise: DenoiseSettings, **params: object) -> Harness:
    path = tmp_path / 'coeffs.yaml'
    save(coefficients(denoise), path)
    overrides = [
        Parameter('coefficients_file', value=str(path)),
        Parameter('log_throttle_s', value=THROTTLE_S),
        Parameter('diagnostics_period_s', value=60.0),  # the test calls publish_diagnostics
    ]
    overrides += [Parameter(k, value=v) for k, v in params.items()]
    return Harness(context, CompensatorNode(context=context, parameter_overrides=overrides))


@pytest.fixture()
def harness_factory(ros_context: object, tmp_path: Path) -> Iterator[Callable[..., Harness]]:
    made: list[Harness] = []

    def make(denoise: DenoiseSettings | None = None, **params: object) -> Harness:
        made.append(start(ros_context, tmp_path, denoise or DenoiseSettings('iir'), **params))
        return made[-1]

    yield make
    for h in made:
        h.close()


class Console:
    """The node's console lines (level, message) from stderr, read as they come."""

    def __init__(self, capfd: pytest.CaptureFixture[str]) -> None:
        self.capfd = capfd
        self.lines: list[tuple[str, str]] = []

    def read(self) -> list[tuple[str, str]]:
        for line in self.capfd.readouterr().err.splitlines():
            match = LINE.match(line)
            assert match, f'not a log line: {line!r}'
            if match.group(2) == 'fog_temp_compensator':
                self.lines.append((match.group(1), match.group(3)))
        return self.lines

    def matching(self, level: str, pattern: str) -> list[str]:
        return [text for lvl, text in self.read() if lvl == level and re.search(pattern, text)]


def three_times(
    console: Console, harness: Harness, cause: Callable[[int], None], level: str, pattern: str
) -> list[str]:
    """Cause the trouble three times (the third after the throttle interval); the lines."""
    console.read()
    console.lines.clear()
    cause(0)
    harness.node.publish_diagnostics()
    assert len(console.matching(level, pattern)) == 1, console.lines
    cause(1)
    harness.node.publish_diagnostics()
    assert len(console.matching(level, pattern)) == 1, 'not throttled'
    time.sleep(THROTTLE_S * 1.05)
    cause(2)
    harness.node.publish_diagnostics()
    lines = console.matching(level, pattern)
    assert len(lines) == 2, console.lines
    return lines


def test_temperature_missing_is_an_error_throttled(
    harness_factory: Callable[..., Harness], capfd: pytest.CaptureFixture[str]
) -> None:
    """At the diagnostics' level, ERROR: the raw rate goes out (it was a WARN line)."""
    h = harness_factory()
    assert h.send_imu(T0, RATE) is None  # waiting for the first temperature (10 s)
    lines = three_times(
        Console(capfd),
        h,
        lambda k: h.send_imu(T0 + 11 + k, RATE),
        'ERROR',
        r'^no temperature received on /imu/temperature: gyro passed through uncorrected',
    )
    assert lines[0].endswith('(1 messages so far)')
    assert lines[1].endswith('(3 messages so far)')


def test_temperature_stale_warns_throttled(
    harness_factory: Callable[..., Harness], capfd: pytest.CaptureFixture[str]
) -> None:
    h = harness_factory()
    h.send_temperature(T0, 25.0)
    h.send_imu(T0 + 1.0, RATE)
    lines = three_times(
        Console(capfd),
        h,
        lambda k: h.send_imu(T0 + 60.0 + k, RATE),
        'WARN',
        r'^temperature on /imu/temperature stale: .* holding the last correction$',
    )
    assert 'last sample 60.0 s before the gyro stamp (temperature_timeout_s 10)' in lines[0]


def test_time_jumps_warn_throttled(
    harness_factory: Callable[..., Harness], capfd: pytest.CaptureFixture[str]
) -> None:
    """A gyro clock that steps 2 s back, once in each report: one line per throttle period."""
    h = harness_factory()
    h.send_temperature(T0, 25.0)

    def cause(k: int) -> None:
        h.send_imu(T0 + 10 * k + 3.0, RATE)
        h.send_imu(T0 + 10 * k + 1.0, RATE)  # 2 s back: out of order, alone
        h.send_imu(T0 + 10 * k + 1.1, RATE)  # back there again: the clock stepped back

    lines = three_times(Console(capfd), h, cause, 'WARN', r'^time jump: ')
    assert lines[0].startswith(
        'time jump: 2 gyro or temperature stamps in a row 1 s or more back (1 since the last '
        'report, 1 in all): filter reset'
    )
    assert '(1 since the last report, 3 in all)' in lines[1]


def test_two_clocks_warn_throttled(
    harness_factory: Callable[..., Harness], capfd: pytest.CaptureFixture[str]
) -> None:
    h = harness_factory()
    for k in range(5):  # temperature stamped 8 s behind the gyro (within the stale time)
        h.send_imu(T0 + k, RATE)
        h.send_temperature(T0 + k - 8.0, 25.0)

    def cause(k: int) -> None:
        h.send_imu(T0 + 5 + k, RATE)
        h.send_temperature(T0 + 5 + k - 8.0, 25.0)

    lines = three_times(
        Console(capfd),
        h,
        cause,
        'WARN',
        r'^/imu/temperature: temperature stamps 8\.0 s behind the gyro stamps on arrival: '
        r'two clocks\?',
    )
    assert lines[0].endswith('misaligned by that much (and stale beyond the stale time)')


@pytest.mark.parametrize(
    ('values', 'level', 'pattern'),
    [
        (
            [math.nan, math.inf, -math.inf],
            'WARN',
            r'^non-finite temperature on /imu/temperature: samples rejected \(1\)$',
        ),
        (
            [-127.0] * 3,
            'ERROR',
            r'^temperature on /imu/temperature reads -127 degC, outside the plausible '
            r'\[-60\.0, 80\.0\] degC \(the calibrated range \+- temperature_fault_margin_degC '
            r'20\): a sensor fault\? 1 readings rejected, the gyro gets stale_policy hold$',
        ),
    ],
    ids=['non-finite', 'sensor fault'],
)
def test_rejected_temperatures_log_throttled(
    harness_factory: Callable[..., Harness],
    capfd: pytest.CaptureFixture[str],
    values: list[float],
    level: str,
    pattern: str,
) -> None:
    h = harness_factory()
    h.send_temperature(T0, 25.0)
    lines = three_times(
        Console(capfd), h, lambda k: h.send_temperature(T0 + 1 + k, values[k]), level, pattern
    )
    assert len(lines) == 2


def test_temperature_clamped_warns_throttled(
    harness_factory: Callable[..., Harness], capfd: pytest.CaptureFixture[str]
) -> None:
    h = harness_factory()
    h.send_temperature(T0, 75.0)  # within temperature_fault_margin_degC of the range
    lines = three_times(
        Console(capfd),
        h,
        lambda k: h.send_imu(T0 + 0.1 * (k + 1), RATE),
        'WARN',
        r'^temperature 75\.00 degC outside the calibrated \[-40\.00, 60\.00\] degC: clamped',
    )
    assert lines[0].endswith('clamped to 60.00 degC')


def test_a_temperature_back_inside_the_range_is_said_as_such(
    harness_factory: Callable[..., Harness], capfd: pytest.CaptureFixture[str]
) -> None:
    """Clamped, then back inside before the report: not 'X degC outside: clamped to X'."""
    h = harness_factory()
    console = Console(capfd)
    h.send_temperature(T0, 60.5)
    h.send_imu(T0 + 0.1, RATE)  # clamped
    for k in range(1, 60):  # down to 57.55 degC at 3 degC/min
        h.send_temperature(T0 + k, 60.5 - 0.05 * k)
        h.send_imu(T0 + k + 0.1, RATE)
    assert h.node.compensator.status.temperature_degC < 60.0
    console.read()
    console.lines.clear()
    h.node.publish_diagnostics()
    lines = console.matching('WARN', r'^temperature outside the calibrated \[-40\.00, 60\.00\]')
    assert len(lines) == 1, console.lines
    assert re.search(r'since the last report: \d+ gyro messages corrected at the range', lines[0])
    assert re.search(r'\(now 5\d\.\d\d degC, inside\)$', lines[0]), lines[0]


def test_tdot_clamped_warns_throttled(
    harness_factory: Callable[..., Harness], capfd: pytest.CaptureFixture[str]
) -> None:
    h = harness_factory(clamp_tdot=True)
    for k in range(61):  # 1.5 degC/min, calibrated range +-0.5
        h.send_temperature(T0 + k, 20.0 + 1.5 * k / 60.0)
    lines = three_times(
        Console(capfd),
        h,
        lambda k: h.send_imu(T0 + 60.1 + 0.1 * k, RATE),
        'WARN',
        r'^Tdot 1\.[45]\d\d degC/min clamped to 0\.500 degC/min \(clamp_tdot: calibrated range\)$',
    )
    assert len(lines) == 2


def test_fallback_to_pass_through_is_an_error_with_the_reason(
    harness_factory: Callable[..., Harness], capfd: pytest.CaptureFixture[str]
) -> None:
    h = harness_factory(stale_policy='none')
    h.send_temperature(T0, 25.0)
    h.send_imu(T0 + 1.0, RATE)
    lines = three_times(
        Console(capfd),
        h,
        lambda k: h.send_imu(T0 + 30.0 + k, RATE),
        'ERROR',
        r'^fallback to pass-through: temperature on /imu/temperature stale',
    )
    assert '(temperature_timeout_s 10, stale_policy none): gyro not corrected' in lines[0]


def test_frame_mismatch_fallback_is_an_error(
    harness_factory: Callable[..., Harness], capfd: pytest.CaptureFixture[str]
) -> None:
    h = harness_factory(require_frame_id_match=True)
    h.send_temperature(T0, 25.0)
    lines = three_times(
        Console(capfd),
        h,
        lambda k: h.send_imu(T0 + 0.1 * (k + 1), RATE, frame_id='other'),
        'ERROR',
        r"^fallback to pass-through: gyro frame_id differs from the calibrated 'imu_link'",
    )
    assert lines[0].endswith('1 messages not corrected')


@pytest.mark.parametrize('hz', [1.0, 10.0])
def test_warm_up_done_is_one_info_line_with_its_duration(
    harness_factory: Callable[..., Harness], capfd: pytest.CaptureFixture[str], hz: float
) -> None:
    h = harness_factory(RECOMMENDED_SETTINGS)
    console = Console(capfd)
    console.read()
    console.lines.clear()
    ready_at = None
    for k in range(int(120 * hz)):  # 0.3 degC/min for 2 min
        stamp = T0 + k / hz
        h.send_temperature(stamp, 20.0 + 0.005 * k / hz)
        if ready_at is None and h.node.compensator.status.estimator_ready:
            ready_at = stamp
    assert ready_at is not None
    lines = console.matching('INFO', r'^Tdot estimator kalman warmed up after ')
    assert lines == [
        f'Tdot estimator kalman warmed up after {ready_at - T0:.1f} s of temperature: '
        'full correction from now on (Tdot terms included)'
    ]
    assert 10.0 < ready_at - T0 < 60.0
    # a gap the Kalman filter bridges (80 s) goes on warm; one longer than temperature_bridge_s
    # (1800 s) restarts the estimate: it warms up again and says so once more
    for k in range(int(120 * hz)):
        h.send_temperature(T0 + 200.0 + k / hz, 21.0)
    assert h.node.compensator.status.counters.temperature_gaps_bridged == 1
    assert len(console.matching('INFO', r'warmed up after')) == 1
    for k in range(int(120 * hz)):
        h.send_temperature(T0 + 2200.0 + k / hz, 21.0)
    assert h.node.compensator.status.counters.temperature_gaps == 1
    assert len(console.matching('INFO', r'warmed up after')) == 2


def test_a_reading_timing_taken_from_the_readings_is_logged_once(
    harness_factory: Callable[..., Harness], capfd: pytest.CaptureFixture[str]
) -> None:
    """Polls every 30 s of 30 readings 1 ms apart, the file silent: one WARN when taken."""
    h = harness_factory()
    console = Console(capfd)
    pattern = r'^reading timing of /imu/temperature taken from its readings'
    for poll in range(1, 9):
        receipt = T0 + 30.0 * poll
        for j in range(30):
            h.send_temperature(receipt + 0.001 * j, 25.0 + 0.0625 * ((poll * 30 + j) // 7))
        h.send_imu(receipt + 0.5, RATE)
        h.node.publish_diagnostics()
        taken = h.node.compensator.status.timing_taken
        assert len(console.matching('WARN', pattern)) == (1 if taken else 0), console.lines
    (line,) = console.matching('WARN', pattern)
    assert f'({taken}): calibrate on bags from this driver' in line
    assert taken.startswith('delivered in polls: temperature_spread_s 1,')
