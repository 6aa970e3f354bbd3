"""Bias learning at rest: the residual constant left after the drift model, per axis.

A FOG's constant bias shifts at every power-on (turn-on repeatability); the chamber calibration
fixes it for one turn-on only. While the unit is still, the drift-corrected rate is that residual
(plus the Earth rate), so averaging it over rest windows learns it, *through* the temperature
model: the T/Tdot correction keeps working and the turn-on shift goes away.

:class:`RestLearner` is fed one drift-corrected gyro sample at a time (and optionally the
accelerometer and an external "at rest" flag). It cuts the stream into windows of ``window_s``;
a window counts as rest when

- the gyro standard deviation on every axis is at most ``gyro_std_max_deg_h`` (no vibration or
  turning),
- with the accelerometer: its standard deviation is at most ``accel_std_max_m_s2`` and the mean of
  the second half differs from the first half by at most ``accel_drift_max_m_s2`` on every axis
  (a slow rotation about a horizontal axis tilts gravity: a *false rest* the gyro variance misses),
- with ``source='external'``: the external flag was true for the whole window (the checks above
  still apply, so a biased external signal cannot force learning during motion).

The mean of a rest window, minus the Earth rate given in ``earth_rate_body_deg_h``, is the
residual. A residual above ``residual_limit_deg_h`` on any axis is reported and *not* used: a
slow rotation about the vertical (invisible to the accelerometer) or a wrong external flag is
bounded by it. The learned value is the mean over all accepted windows since start (the turn-on
bias is constant for a turn-on); the value applied follows it with a first-order lag of
``time_constant_s`` (no step in the output).

Two more ways in: :meth:`RestLearner.start_from` starts from a value learned at an earlier turn-on
(``restfile.py``: the file it is kept in), replaced by this turn-on's first accepted window; and
:meth:`RestLearner.force_next_window` accepts the next window without the rest checks (a
known-still moment, "learn now"), still bounded by ``residual_limit_deg_h``.

Earth rate: with ``earth_rate_body_deg_h`` left at zero it is learned into the constant. That is
right while the unit keeps the orientation it had at rest, and wrong by up to the Earth rate
(15 deg/h, split over the axes by the orientation) once it turns; give it (``earth.py``:
``earth_rate_body_deg_h(latitude, orientation)``) when the resting orientation is known.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from fog_temp_comp.core.units import DEG_H_PER_RAD_S, RAD_S_PER_DEG_H

REST_SOURCES = ('imu', 'external')
Vector = tuple[float, float, float]


@dataclass(frozen=True)
class RestSettings:
    """Bias learning at rest (off by default); units in the names, see the module docstring."""

    enabled: bool = False
    source: str = 'imu'
    window_s: float = 10.0
    gyro_std_max_deg_h: float = 100.0
    accel_std_max_m_s2: float = 0.05
    accel_drift_max_m_s2: float = 0.01
    residual_limit_deg_h: float = 20.0
    time_constant_s: float = 10.0
    earth_rate_body_deg_h: Vector = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if self.source not in REST_SOURCES:
            raise ValueError(f'rest source must be one of {REST_SOURCES}, got {self.source!r}')
        for name in (
            'window_s',
            'gyro_std_max_deg_h',
            'accel_std_max_m_s2',
            'accel_drift_max_m_s2',
            'residual_limit_deg_h',
            'time_constant_s',
        ):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and value > 0 and math.isfinite(value)):
                raise ValueError(f'{name} must be a finite number > 0, got {value!r}')
        earth = tuple(float(v) for v in self.earth_rate_body_deg_h)
        if len(earth) != 3 or not all(math.isfinite(v) for v in earth):
            raise ValueError(f'earth_rate_body_deg_h must be 3 finite numbers, got {earth!r}')
        object.__setattr__(self, 'earth_rate_body_deg_h', earth)


@dataclass
class RestStatus:
    """What the learner has seen and applies (for diagnostics), deg/h per axis."""

    at_rest: bool = False  # verdict on the last complete window
    windows_rest: int = 0  # accepted and learned from
    windows_motion: int = 0  # gyro or accelerometer too noisy
    windows_tilting: int = 0  # accelerometer mean moved within the window (slow rotation)
    windows_not_flagged: int = 0  # source 'external' and the flag was not true throughout
    windows_over_limit: int = 0  # quiet, but the residual exceeded the limit: not used
    residual_over_limit: bool = False  # the last quiet window exceeded the limit
    last_residual_deg_h: Vector = (math.nan, math.nan, math.nan)  # last quiet window's mean
    learned_deg_h: Vector = (0.0, 0.0, 0.0)  # mean over the accepted windows
    learned_std_deg_h: Vector = (math.nan, math.nan, math.nan)  # its noise (std / sqrt(n))
    applied_deg_h: Vector = (0.0, 0.0, 0.0)  # subtracted now (follows learned_deg_h)
    samples_learned: int = 0
    learned_at_stamp_s: float = math.nan  # end of the last accepted window (sensor time, s)
    learned_temperature_degC: float = math.nan  # temperature then
    initial_deg_h: Vector | None = None  # started from (start_from), until a window is learned
    force_pending: bool = False  # force_next_window() called, its window not judged yet
    windows_forced: int = 0  # forced windows learned from
    forced_outcome: str = ''  # what the last forced window gave


@dataclass
class _Window:
    start_s: float = math.nan
    n: int = 0
    gyro: list[float] = field(default_factory=lambda: [0.0] * 6)  # sums, sums of squares
    gyro_ref: Vector = (0.0, 0.0, 0.0)  # first sample (shifted sums)
    accel_n: list[int] = field(default_factory=lambda: [0, 0])  # per half
    accel: list[float] = field(default_factory=lambda: [0.0] * 12)  # half 1/2 sums, squares
    flagged: bool = True
    forced: bool = False  # accepted without the rest checks (force_next_window)


class RestLearner:
    """Per-axis residual bias learned at rest; state carried explicitly (sample by sample).

    Parameters
    ----------
    settings : RestSettings
        Thresholds, window, bound and smoothing.

    """

    def __init__(self, settings: RestSettings) -> None:
        self.settings = settings
        #: temperature (degC) of the latest sample, kept by the compensator (for the record)
        self.temperature_degC = math.nan
        self._initial: Vector | None = None  # deg/h, from start_from
        self._clear()

    def reset(self) -> None:
        """Forget everything learned in this run (a time jump: another run); keep the start."""
        self._clear()

    def _clear(self) -> None:
        self.status = RestStatus()
        self._window = _Window()
        self._external = False
        self._force = False
        start = self._initial or (0.0, 0.0, 0.0)
        self._applied = [v * RAD_S_PER_DEG_H for v in start]  # rad/s
        self._target = list(self._applied)  # rad/s
        self._last_stamp_s = math.nan
        self._sums = [0.0, 0.0, 0.0]  # deg/h, over accepted windows
        self._sq_sums = [0.0, 0.0, 0.0]
        if self._initial is not None:
            self.status.initial_deg_h = self._initial
            self.status.learned_deg_h = self._initial

    def start_from(self, bias_deg_h: Vector) -> str | None:
        """Start from a residual learned earlier (deg/h): applied at once, until replaced.

        Call before the first sample. The first window accepted in this run replaces it (the
        turn-on shift is new at every power-on). Bounded like a window: a value above
        ``residual_limit_deg_h`` (or not finite) is not used. Returns None when applied, else
        the reason it was not.
        """
        values = tuple(float(v) for v in bias_deg_h)
        limit = self.settings.residual_limit_deg_h
        if len(values) != 3 or not all(math.isfinite(v) for v in values):
            return f'initial bias {values} deg/h is not 3 finite numbers: not used'
        if any(abs(v) > limit for v in values):
            return (
                f'initial bias {tuple(round(v, 3) for v in values)} deg/h exceeds '
                f'residual_limit_deg_h {limit:g}: not used'
            )
        self._initial = (values[0], values[1], values[2])
        self._clear()
        return None

    def force_next_window(self) -> None:
        """A known-still moment ("learn now"): accept the next window without the rest checks.

        The next window that starts after this call is learned from whatever the gyro and
        accelerometer variance (or the external flag) say; its residual is still bounded by
        ``residual_limit_deg_h``. The outcome is in ``status.forced_outcome``.
        """
        self._force = True
        self.status.force_pending = True

    def set_external_rest(self, at_rest: bool) -> None:
        """The vehicle's "at rest" signal; a false value spoils the current window."""
        self._external = bool(at_rest)
        if not at_rest:
            self._window.flagged = False

    @property
    def applied_rad_s(self) -> Vector:
        """Residual subtracted now, rad/s."""
        a = self._applied
        return (a[0], a[1], a[2])

    def update(
        self, stamp_s: float, x: float, y: float, z: float, accel_m_s2: Vector | None = None
    ) -> Vector:
        """Feed one drift-corrected rate (rad/s); return the residual to subtract (rad/s)."""
        last = self._last_stamp_s
        window = self._window
        settings = self.settings
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            return self.applied_rad_s
        if not stamp_s > last or stamp_s - last > settings.window_s:  # start, gap or step back
            self._force = self._force or window.forced  # a forced window cut short: re-armed
            self._start_window(stamp_s, x, y, z)
            window = self._window
        elif stamp_s - window.start_s >= settings.window_s:
            self._close_window()
            self._start_window(stamp_s, x, y, z)
            window = self._window
        else:
            alpha = min((stamp_s - last) / settings.time_constant_s, 1.0)
            a, t = self._applied, self._target
            a[0] += (t[0] - a[0]) * alpha
            a[1] += (t[1] - a[1]) * alpha
            a[2] += (t[2] - a[2]) * alpha
        self._last_stamp_s = stamp_s
        r = window.gyro_ref
        g = window.gyro
        dx, dy, dz = x - r[0], y - r[1], z - r[2]
        g[0] += dx
        g[1] += dy
        g[2] += dz
        g[3] += dx * dx
        g[4] += dy * dy
        g[5] += dz * dz
        window.n += 1
        # a non-finite accelerometer sample is left out (NaN would pass every check below)
        if accel_m_s2 is not None and math.isfinite(sum(accel_m_s2)):
            half = 0 if stamp_s - window.start_s < 0.5 * settings.window_s else 1
            acc = window.accel
            o = 6 * half
            ax, ay, az = accel_m_s2
            acc[o] += ax
            acc[o + 1] += ay
            acc[o + 2] += az
            acc[o + 3] += ax * ax
            acc[o + 4] += ay * ay
            acc[o + 5] += az * az
            window.accel_n[half] += 1
        return self.applied_rad_s

    def _start_window(self, stamp_s: float, x: float, y: float, z: float) -> None:
        self._window = _Window(
            start_s=stamp_s, gyro_ref=(x, y, z), flagged=self._external, forced=self._force
        )
        self._force = False

    def _close_window(self) -> None:
        """Judge the finished window; learn from it if it is rest within the bound."""
        window, settings, status = self._window, self.settings, self.status
        n = window.n
        status.at_rest = False
        if n < 2:
            if window.forced:  # too short to learn from: stay armed for the next one
                self._force = True
            return
        g = window.gyro
        means = [0.0, 0.0, 0.0]
        for j in range(3):
            mean_shift = g[j] / n
            var = max(g[3 + j] / n - mean_shift * mean_shift, 0.0) * n / (n - 1)
            if (
                not window.forced
                and math.sqrt(var) * DEG_H_PER_RAD_S > settings.gyro_std_max_deg_h
            ):
                status.windows_motion += 1
                return
            means[j] = (window.gyro_ref[j] + mean_shift) * DEG_H_PER_RAD_S
        if not window.forced:
            if not self._accel_quiet(window):
                return
            if settings.source == 'external' and not (window.flagged and self._external):
                status.windows_not_flagged += 1
                return
        earth = settings.earth_rate_body_deg_h
        residual = (means[0] - earth[0], means[1] - earth[1], means[2] - earth[2])
        status.last_residual_deg_h = residual
        status.residual_over_limit = any(abs(v) > settings.residual_limit_deg_h for v in residual)
        text = ', '.join(f'{v:.3f}' for v in residual)
        if window.forced:
            status.force_pending = self._force
        if status.residual_over_limit:
            status.windows_over_limit += 1
            if window.forced:
                status.forced_outcome = (
                    f'forced window of {n} samples refused: residual {text} deg/h (x, y, z) '
                    f'exceeds residual_limit_deg_h {settings.residual_limit_deg_h:g} (moving?)'
                )
            return
        if window.forced:
            status.windows_forced += 1
            status.forced_outcome = (
                f'forced window of {n} samples learned: residual {text} deg/h (x, y, z)'
            )
        status.at_rest = True
        status.learned_at_stamp_s = self._last_stamp_s
        status.learned_temperature_degC = self.temperature_degC
        status.windows_rest += 1
        status.samples_learned += n
        for j in range(3):
            self._sums[j] += residual[j] * n
            var = max(g[3 + j] / n - (g[j] / n) ** 2, 0.0) * DEG_H_PER_RAD_S**2
            self._sq_sums[j] += var * n
        total = status.samples_learned
        learned = tuple(s / total for s in self._sums)
        status.learned_deg_h = (learned[0], learned[1], learned[2])
        status.learned_std_deg_h = tuple(  # type: ignore[assignment]
            math.sqrt(s / total / total) for s in self._sq_sums
        )
        self._target = [v * RAD_S_PER_DEG_H for v in learned]

    def _accel_quiet(self, window: _Window) -> bool:
        settings, status = self.settings, self.status
        n1, n2 = window.accel_n
        if n1 < 2 or n2 < 2:  # no accelerometer: the gyro variance alone decides
            return True
        acc = window.accel
        for j in range(3):
            m1, m2 = acc[j] / n1, acc[6 + j] / n2
            n = n1 + n2
            mean = (acc[j] + acc[6 + j]) / n
            var = max((acc[3 + j] + acc[9 + j]) / n - mean * mean, 0.0)
            if math.sqrt(var) > settings.accel_std_max_m_s2:
                status.windows_motion += 1
                return False
            if abs(m2 - m1) > settings.accel_drift_max_m_s2:
                status.windows_tilting += 1
                return False
        return True

    def finish(self) -> RestStatus:
        """Status, with ``applied_deg_h`` filled in."""
        self.status.applied_deg_h = tuple(  # type: ignore[assignment]
            v * DEG_H_PER_RAD_S for v in self._applied
        )
        return self.status
