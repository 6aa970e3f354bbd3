"""Synthetic thermal-chamber runs of a 3-axis FOG, following the paper's test plan.

Pure numpy: :func:`simulate_run` returns arrays; :mod:`~fog_temp_comp.bag.bagio` writes them.

Physics (all documented units):

- chamber setpoint: piecewise-linear profile (cycles at a given degC/min between ``low_degC``
  and ``high_degC`` with soaks at the ends, or a constant soak);
- chamber air: the setpoint, or (``chamber_period_s > 0``) the response of a second-order
  controller to it, which lags the ramps and overshoots at their ends; plus a controller
  oscillation (``soak_oscillation_degC`` on soaks, ``cycle_oscillation_degC`` on cycles);
- gyro housing, where the temperature sensor sits: first-order lag of the chamber air, time
  constant ``lag_s``; with ``power_on_heating_degC`` the unit's own dissipation warms it that
  much above the air from each run's start (a power-on: the run starts in equilibrium with the
  air, and the housing rises through the same lag);
- fibre coil: first-order lag of the housing, time constant ``coil_lag_s`` (0: the sensor reads
  the coil, as in the paper); the coil temperature and its exact rate drive the drift;
- drift per axis: ``D = d0 + dt*T + dtdot*Tdot + t2*T^2 + t3*T^3 + t_tdot*T*Tdot`` (deg/h), x
  near the paper's Table 1 (the last three terms are zero by default), of the coil's
  temperature, or of each axis's own coil (``axis_coil_lags_s``);
- gyro noise: angle random walk (white rate), a Gauss-Markov bias instability and a slowly
  wandering bias (rate random walk);
- temperature sensor: white noise, then quantization (1/16 degC).

:data:`SimulationConfig` defaults reproduce the shipped sample bags (the paper's model exactly);
:data:`REALISTIC` switches on every effect above and is what the accuracy study uses.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from fog_temp_comp.core.model import PAPER_TERMS, DriftModel, Range
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.core.units import RAD_S_PER_DEG_H, S_PER_H, S_PER_MIN
from fog_temp_comp.tools.sim_noise import correlated, gauss_markov, quantize

FloatArray = NDArray[np.float64]

#: the paper's test plan
CYCLE_RATES_DEGC_PER_MIN = (0.2, 0.3, 0.4, 0.6, 0.8, 1.0)
SOAK_TEMPERATURES_DEGC = (-40.0, -20.0, 10.0, 30.0)
#: calibration run of the paper
TRAINING_RUN = 'cycle_0p2'

#: true coefficients, rows const/T/Tdot, columns x/y/z; x is the paper's Table 1 (wavelet column)
TRUE_COEFFICIENTS = np.array(
    [
        [-12.5395, 3.20, -0.85],  # d0_deg_h
        [-8.68e-4, 2.4e-3, -1.6e-3],  # dt_deg_h_per_degC
        [0.9287, -0.62, 0.45],  # dtdot_deg_h_per_degC_per_min
    ]
)
#: the small nonlinearity of :data:`REALISTIC`, deg/h/degC^2 per axis (about 0.02 deg/h away
#: from the best straight line over -40..60 degC)
REALISTIC_T2_COEFFICIENTS = (2.0e-5, -1.5e-5, 1.0e-5)


@dataclass(frozen=True)
class SimulationConfig:
    """Sensor and chamber settings (units in the names).

    The fields up to ``coefficients`` are the original model (the shipped bags); the fields
    after it add realism and default to "off", so the defaults reproduce the original runs
    bit for bit.

    Attributes
    ----------
    lag_s : float
        Time constant of the first-order lag from chamber air to the gyro housing (where the
        temperature sensor is), s.
    coefficients : ndarray, shape (3, 3)
        Rows const/T/Tdot (deg/h, deg/h/degC, deg/h/(degC/min)), columns x/y/z.
    coil_lag_s : float
        Time constant of the first-order lag from the housing sensor to the fibre coil, s; 0
        means the sensor reads the coil.
    chamber_period_s : float
        Natural period of the chamber controller, modelled as a second-order low-pass from
        setpoint to air temperature, s; 0 means the air follows the setpoint exactly.
    chamber_damping : float
        Damping ratio of that controller (below 1: overshoot at the end of each ramp).
    cycle_oscillation_degC : float
        Amplitude of the controller oscillation during cycle runs, degC (period
        ``soak_oscillation_period_s``); ``soak_oscillation_degC`` is the one on soak runs.
    t2_coefficients, t3_coefficients, t_tdot_coefficients : tuple of 3 float
        Nonlinear drift terms per axis: deg/h/degC^2 times T^2, deg/h/degC^3 times T^3 and
        deg/h/(degC degC/min) times T * Tdot.
    bias_random_walk_deg_h_per_sqrt_h : float
        Rate random walk of the gyro bias (a slowly wandering bias), deg/h/sqrt(h).
    sensor_lag_s : float
        Time constant of a first-order lag from the fibre coil to the temperature sensor, s:
        the sensor sits *behind* the coil and reads it late (0: the sensor reads the housing,
        which the coil follows through ``coil_lag_s``).
    turn_on_shift_deg_h : tuple of 3 float
        Constant bias added at this power-on (turn-on to turn-on repeatability), deg/h; not in
        ``true_drift_deg_h`` (the temperature part), in ``turn_on_shift_deg_h`` of the run.
    motion_period_s, motion_fraction : float
        Vehicle phases: every ``motion_period_s`` the unit rests first, then moves (a shaking
        rotation of ``motion_rate_deg_s`` amplitude on each axis) for the last
        ``motion_fraction`` of the period; period 0 = always at rest (a chamber).
    motion_rate_deg_s : float
        Amplitude of that rotation (deg/s); it is in ``true_rotation_rad_s`` of the run.
    temp_noise_correlation_s : float
        Correlation time of the temperature sensor's noise before quantization, s: a first-order
        (AR(1)) process of std ``temp_noise_degC`` (a sensor that averages internally, or
        drifts); 0 means white, as the filters assume.
    temp_step_nonlinearity : float
        Differential nonlinearity of the temperature sensor's quantizer, in steps (0 to < 1):
        each boundary between two readings is displaced by a fixed amount, uniform within
        +-half this, the same on every run (an ADC's uneven codes); 0 means ideal steps.
    axis_coil_lags_s : tuple of 3 float
        Per axis (x, y, z), the time constant of a further first-order lag from the coil
        above to that axis's own coil, s: three coils at three places, one temperature sensor
        (0: the axis's coil is that coil). A sensor behind the coil can so be ahead of another
        axis's coil.

    """

    imu_hz: float = 10.0
    temp_hz: float = 1.0
    start_stamp_s: float = 1_700_000_000.0
    low_degC: float = -40.0
    high_degC: float = 60.0
    start_degC: float = 20.0
    cycle_soak_s: float = 3600.0
    soak_duration_s: float = 7200.0
    soak_oscillation_degC: float = 0.2
    soak_oscillation_period_s: float = 1800.0
    lag_s: float = 600.0
    #: std of 10 s means of the white rate noise (deg/h), the paper's constant-temperature level
    arw_10s_deg_h: float = 0.02
    bias_instability_deg_h: float = 0.005
    bias_correlation_s: float = 600.0
    temp_noise_degC: float = 0.02
    temp_quantum_degC: float = 1.0 / 16.0
    coefficients: FloatArray = field(default_factory=lambda: TRUE_COEFFICIENTS.copy())
    coil_lag_s: float = 0.0
    chamber_period_s: float = 0.0
    chamber_damping: float = 0.5
    cycle_oscillation_degC: float = 0.0
    t2_coefficients: tuple[float, float, float] = (0.0, 0.0, 0.0)
    t_tdot_coefficients: tuple[float, float, float] = (0.0, 0.0, 0.0)
    t3_coefficients: tuple[float, float, float] = (0.0, 0.0, 0.0)
    bias_random_walk_deg_h_per_sqrt_h: float = 0.0
    sensor_lag_s: float = 0.0
    turn_on_shift_deg_h: tuple[float, float, float] = (0.0, 0.0, 0.0)
    motion_period_s: float = 0.0
    motion_fraction: float = 0.5
    motion_rate_deg_s: float = 5.0
    temp_noise_correlation_s: float = 0.0
    temp_step_nonlinearity: float = 0.0
    power_on_heating_degC: float = 0.0
    axis_coil_lags_s: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        for name in ('imu_hz', 'temp_hz', 'lag_s', 'soak_duration_s'):
            if not getattr(self, name) > 0:
                raise ValueError(f'{name} must be > 0, got {getattr(self, name)}')
        for name in (
            'coil_lag_s',
            'chamber_period_s',
            'cycle_oscillation_degC',
            'bias_random_walk_deg_h_per_sqrt_h',
            'sensor_lag_s',
            'motion_period_s',
            'motion_rate_deg_s',
            'temp_noise_correlation_s',
            'power_on_heating_degC',
        ):
            if not getattr(self, name) >= 0:
                raise ValueError(f'{name} must be >= 0, got {getattr(self, name)}')
        if not 0.0 <= self.temp_step_nonlinearity < 1.0:
            raise ValueError(
                'temp_step_nonlinearity must be within 0..1 (steps), got '
                f'{self.temp_step_nonlinearity}'
            )
        if not self.chamber_damping > 0:
            raise ValueError(f'chamber_damping must be > 0, got {self.chamber_damping}')
        if not 0.0 <= self.motion_fraction <= 1.0:
            raise ValueError(f'motion_fraction must be within [0, 1], got {self.motion_fraction}')
        for name in (
            't2_coefficients',
            't3_coefficients',
            't_tdot_coefficients',
            'turn_on_shift_deg_h',
            'axis_coil_lags_s',
        ):
            value = tuple(float(v) for v in getattr(self, name))
            if len(value) != 3 or not all(np.isfinite(value)):
                raise ValueError(f'{name} must be 3 finite numbers (x, y, z), got {value}')
            object.__setattr__(self, name, value)
        if min(self.axis_coil_lags_s) < 0:
            raise ValueError(f'axis_coil_lags_s must be >= 0, got {self.axis_coil_lags_s}')

    @property
    def terms(self) -> tuple[str, ...]:
        """Model terms of the true drift: the paper's, plus the nonlinear ones in use."""
        extra = [
            term
            for term, values in (
                ('T2', self.t2_coefficients),
                ('T3', self.t3_coefficients),
                ('T_Tdot', self.t_tdot_coefficients),
            )
            if any(values)
        ]
        return (*PAPER_TERMS, *extra)

    @property
    def true_coefficients(self) -> FloatArray:
        """Coefficients of :attr:`terms`, shape (len(terms), 3)."""
        rows = [np.asarray(self.coefficients, dtype=np.float64)]
        if any(self.t2_coefficients):
            rows.append(np.array([self.t2_coefficients]))
        if any(self.t3_coefficients):
            rows.append(np.array([self.t3_coefficients]))
        if any(self.t_tdot_coefficients):
            rows.append(np.array([self.t_tdot_coefficients]))
        return np.concatenate(rows, axis=0)


#: the accuracy study's chamber: a housing sensor 3 min ahead of the coil, a controller that
#: overshoots and oscillates, a small T^2 nonlinearity and a wandering bias; 1 Hz streams
REALISTIC = SimulationConfig(
    imu_hz=1.0,
    temp_hz=1.0,
    soak_oscillation_degC=0.3,
    soak_oscillation_period_s=1200.0,
    coil_lag_s=180.0,
    chamber_period_s=900.0,
    chamber_damping=0.5,
    cycle_oscillation_degC=0.1,
    t2_coefficients=REALISTIC_T2_COEFFICIENTS,
    bias_random_walk_deg_h_per_sqrt_h=0.003,
)


def true_model(cfg: SimulationConfig | None = None) -> DriftModel:
    """The simulator's drift model as a :class:`DriftModel` (default: the paper's terms)."""
    if cfg is None:
        return DriftModel(PAPER_TERMS, TRUE_COEFFICIENTS, Range(-60.0, 80.0), Range(-2.0, 2.0))
    return DriftModel(cfg.terms, cfg.true_coefficients, Range(-60.0, 80.0), Range(-2.0, 2.0))


@dataclass(frozen=True)
class SimulatedRun:
    """One chamber run.

    Attributes
    ----------
    imu_stamps_s : (N,) ; rates_rad_s : (N, 3) measured gyro output
    temp_stamps_s : (M,) ; temperature_degC : (M,) measured (noisy, quantized) temperature
    true_temperature_degC, true_tdot_degC_per_min : (N,) coil temperature and rate at imu stamps
    true_drift_deg_h : (N, 3) temperature drift in the gyro output (the part to remove)
    turn_on_shift_deg_h : (3,) constant bias of this power-on, also in the output
    true_rotation_rad_s : (N, 3) or None, the vehicle's rotation (motion phases), also in it

    """

    name: str
    kind: str
    setpoint: float
    imu_stamps_s: FloatArray
    rates_rad_s: FloatArray
    temp_stamps_s: FloatArray
    temperature_degC: FloatArray
    true_temperature_degC: FloatArray
    true_tdot_degC_per_min: FloatArray
    true_drift_deg_h: FloatArray
    turn_on_shift_deg_h: FloatArray = field(default_factory=lambda: np.zeros(3))
    true_rotation_rad_s: FloatArray | None = None

    def oracle_error_rad_s(self, corrected_rad_s: FloatArray) -> FloatArray:
        """Error of a corrected rate (rad/s, (N, 3)) against the oracle: the vehicle's rotation."""
        out = np.asarray(corrected_rad_s, dtype=np.float64)
        return out if self.true_rotation_rad_s is None else out - self.true_rotation_rad_s

    def select(self, imu: NDArray[np.bool_], temp: NDArray[np.bool_]) -> SimulatedRun:
        """The run's gyro messages where ``imu`` (N,) is true, temperatures where ``temp`` (M,)."""
        rotation = self.true_rotation_rad_s
        return dataclasses.replace(
            self,
            imu_stamps_s=self.imu_stamps_s[imu],
            rates_rad_s=self.rates_rad_s[imu],
            temp_stamps_s=self.temp_stamps_s[temp],
            temperature_degC=self.temperature_degC[temp],
            true_temperature_degC=self.true_temperature_degC[imu],
            true_tdot_degC_per_min=self.true_tdot_degC_per_min[imu],
            true_drift_deg_h=self.true_drift_deg_h[imu],
            true_rotation_rad_s=None if rotation is None else rotation[imu],
        )

    def as_record(self, frame_id: str = 'imu_link') -> ChamberRecord:
        """The run as if read back from a bag (topics ``/imu/data_raw``, ``/imu/temperature``)."""
        return ChamberRecord(
            path=Path(self.name),
            imu_topic='/imu/data_raw',
            temp_topic='/imu/temperature',
            frame_id=frame_id,
            imu_stamps_s=self.imu_stamps_s,
            rates_rad_s=self.rates_rad_s,
            temp_stamps_s=self.temp_stamps_s,
            temperature_degC=self.temperature_degC,
        )


def run_name(kind: str, setpoint: float) -> str:
    """``cycle_0p2`` for a 0.2 degC/min cycle, ``soak_m40`` for a -40 degC soak."""
    text = f'{setpoint:g}'.replace('-', 'm').replace('.', 'p')
    return f'{kind}_{text}'


def paper_plan() -> list[tuple[str, float]]:
    """(kind, setpoint) of every run in the paper's plan, training run first."""
    return [('cycle', r) for r in CYCLE_RATES_DEGC_PER_MIN] + [
        ('soak', t) for t in SOAK_TEMPERATURES_DEGC
    ]


def chamber_profile(
    kind: str, setpoint: float, cfg: SimulationConfig
) -> tuple[FloatArray, FloatArray]:
    """Breakpoints (s from start, degC) of the chamber setpoint; linear in between."""
    if kind == 'cycle':
        rate = setpoint / S_PER_MIN  # degC/s
        if not rate > 0:
            raise ValueError(f'cycle rate must be > 0 degC/min, got {setpoint}')
        points = [(0.0, cfg.start_degC)]

        def go(target: float) -> None:
            t, x = points[-1]
            points.append((t + abs(target - x) / rate, target))

        def hold() -> None:
            t, x = points[-1]
            points.append((t + cfg.cycle_soak_s, x))

        points.append((cfg.cycle_soak_s / 2, cfg.start_degC))
        go(cfg.high_degC)
        hold()
        go(cfg.low_degC)
        hold()
        go(cfg.start_degC)
        t_end, x_end = points[-1]
        points.append((t_end + cfg.cycle_soak_s / 2, x_end))
        arr = np.array(points)
        return arr[:, 0], arr[:, 1]
    if kind == 'soak':
        return np.array([0.0, cfg.soak_duration_s]), np.array([setpoint, setpoint])
    raise ValueError(f"kind must be 'cycle' or 'soak', got {kind!r}")


def first_order_lag(x: FloatArray, dt_s: float, tau_s: float) -> tuple[FloatArray, FloatArray]:
    """Exact first-order lag of a piecewise-constant input, starting in steady state.

    Parameters
    ----------
    x : ndarray, shape (n,)
        Input on a uniform grid of ``dt_s`` seconds (degC).
    dt_s, tau_s : float
        Grid step and time constant (s, > 0).

    Returns
    -------
    y : ndarray, shape (n,)
        Lagged signal (degC).
    ydot : ndarray, shape (n,)
        Its exact rate ``(x - y) / tau_s`` in degC/min.

    """
    a = np.exp(-dt_s / tau_s)
    y, _ = signal.lfilter([1 - a], [1, -a], x, zi=[a * x[0]])
    y = np.asarray(y, dtype=np.float64)
    return y, (x - y) / tau_s * S_PER_MIN


def chamber_air(setpoint_degC: FloatArray, dt_s: float, cfg: SimulationConfig) -> FloatArray:
    """Chamber air temperature (degC) for a setpoint on a uniform grid of ``dt_s`` seconds.

    A second-order controller ``wn^2 / (s^2 + 2 zeta wn s + wn^2)`` with ``wn = 2 pi /
    chamber_period_s`` and ``zeta = chamber_damping``, at rest on the first setpoint; the
    setpoint itself when ``chamber_period_s`` is 0.
    """
    if cfg.chamber_period_s <= 0:
        return setpoint_degC
    wn = 2 * np.pi / cfg.chamber_period_s
    zeta = cfg.chamber_damping
    num, den, _ = signal.cont2discrete(([wn**2], [1.0, 2 * zeta * wn, wn**2]), dt_s, method='zoh')
    start = setpoint_degC[0]
    air = signal.lfilter(np.ravel(num), den, setpoint_degC - start)
    return np.asarray(air, dtype=np.float64) + start


def simulate_run(
    kind: str, setpoint: float, cfg: SimulationConfig | None = None, *, seed: int = 0
) -> SimulatedRun:
    """Simulate one run (``kind`` 'cycle' with setpoint in degC/min, or 'soak' in degC).

    Random draws of the original model come from ``default_rng(seed)`` in the original order,
    so the default configuration reproduces the shipped runs; the realism fields draw from a
    second generator ``default_rng((seed, 1))``.
    """
    cfg = cfg or SimulationConfig()
    rng = np.random.default_rng(seed)
    extra_rng = np.random.default_rng((seed, 1))
    duration, t_grid, coil_t, coil_tdot, sensor_t = _thermal_path(
        kind, setpoint, cfg, rng, extra_rng
    )
    n_imu = int(np.floor(duration * cfg.imu_hz))
    t_imu = np.arange(n_imu) / cfg.imu_hz
    true_t = np.interp(t_imu, t_grid, coil_t)
    true_tdot = np.interp(t_imu, t_grid, coil_tdot)
    drift = _drift_deg_h(cfg, t_imu, t_grid, coil_t, true_t, true_tdot)

    sigma_white = cfg.arw_10s_deg_h * np.sqrt(10.0 * cfg.imu_hz)  # per-sample std, deg/h
    white = rng.normal(0.0, sigma_white, size=(n_imu, 3))
    bias = gauss_markov(
        rng, n_imu, 1.0 / cfg.imu_hz, cfg.bias_instability_deg_h, cfg.bias_correlation_s
    )
    rates = drift + white + bias
    if cfg.bias_random_walk_deg_h_per_sqrt_h > 0 and n_imu:
        step = cfg.bias_random_walk_deg_h_per_sqrt_h * np.sqrt(1.0 / cfg.imu_hz / S_PER_H)
        rates = rates + np.cumsum(extra_rng.normal(0.0, step, size=(n_imu, 3)), axis=0)
    shift = np.array(cfg.turn_on_shift_deg_h)
    if np.any(shift):
        rates = rates + shift
    rates = rates * RAD_S_PER_DEG_H
    rotation = _vehicle_rotation(cfg, t_imu)
    if rotation is not None:
        rates = rates + rotation

    n_temp = int(np.floor(duration * cfg.temp_hz))
    t_temp = np.arange(n_temp) / cfg.temp_hz
    noise = rng.normal(0.0, cfg.temp_noise_degC, n_temp)
    if cfg.temp_noise_correlation_s > 0 and n_temp:
        noise = correlated(noise, np.exp(-1.0 / (cfg.temp_hz * cfg.temp_noise_correlation_s)))
    temp = np.interp(t_temp, t_grid, sensor_t) + noise
    if cfg.temp_quantum_degC > 0:
        temp = quantize(temp, cfg.temp_quantum_degC, cfg.temp_step_nonlinearity)
    return SimulatedRun(
        name=run_name(kind, setpoint),
        kind=kind,
        setpoint=float(setpoint),
        imu_stamps_s=cfg.start_stamp_s + t_imu,
        rates_rad_s=rates,
        temp_stamps_s=cfg.start_stamp_s + t_temp,
        temperature_degC=temp,
        true_temperature_degC=true_t,
        true_tdot_degC_per_min=true_tdot,
        true_drift_deg_h=drift,
        turn_on_shift_deg_h=shift,
        true_rotation_rad_s=rotation,
    )


def _drift_deg_h(
    cfg: SimulationConfig,
    t_imu: FloatArray,
    t_grid: FloatArray,
    coil_t: FloatArray,
    true_t: FloatArray,
    true_tdot: FloatArray,
) -> FloatArray:
    """The temperature drift at the gyro stamps, (N, 3) deg/h.

    Each axis's coil follows the reference coil (``coil_t`` on the 1 s grid, degC; ``true_t``
    and ``true_tdot`` at the gyro stamps) through its own ``axis_coil_lags_s`` (0: the
    reference coil itself).
    """
    model = true_model(cfg)
    drift = model.drift_deg_h(true_t, true_tdot)
    for axis, lag_s in enumerate(cfg.axis_coil_lags_s):
        if lag_s > 0:
            axis_t, axis_tdot = first_order_lag(coil_t, 1.0, lag_s)
            drift[:, axis] = model.drift_deg_h(
                np.interp(t_imu, t_grid, axis_t), np.interp(t_imu, t_grid, axis_tdot)
            )[:, axis]
    return drift


def _thermal_path(
    kind: str,
    setpoint: float,
    cfg: SimulationConfig,
    rng: np.random.Generator,
    extra_rng: np.random.Generator,
) -> tuple[float, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Chamber air to housing to coil to sensor, on a 1 s grid.

    Returns the run's duration (s), the grid (s), the coil's temperature (degC) and Tdot (as
    :func:`first_order_lag` gives it, degC/min) and what the sensor reads (degC), noise-free.
    """
    bp_t, bp_x = chamber_profile(kind, setpoint, cfg)
    duration = float(bp_t[-1])
    # 1 s simulation grid for the thermal lags (exact first-order discretisation)
    dt = 1.0
    t_grid = np.arange(0.0, duration + dt, dt)
    chamber = chamber_air(np.interp(t_grid, bp_t, bp_x), dt, cfg)
    if kind == 'soak' and cfg.soak_oscillation_degC > 0:
        phase = rng.uniform(0, 2 * np.pi)
        chamber = chamber + cfg.soak_oscillation_degC * np.sin(
            2 * np.pi * t_grid / cfg.soak_oscillation_period_s + phase
        )
    if kind == 'cycle' and cfg.cycle_oscillation_degC > 0:
        phase = extra_rng.uniform(0, 2 * np.pi)
        chamber = chamber + cfg.cycle_oscillation_degC * np.sin(
            2 * np.pi * t_grid / cfg.soak_oscillation_period_s + phase
        )
    if cfg.power_on_heating_degC > 0:
        # the dissipation switches on after the first instant: the housing's environment steps
        # up by the heating, from equilibrium with the air
        chamber = chamber + cfg.power_on_heating_degC * (t_grid > 0)
    housing_t, housing_tdot = first_order_lag(chamber, dt, cfg.lag_s)
    if cfg.coil_lag_s > 0:
        coil_t, coil_tdot = first_order_lag(housing_t, dt, cfg.coil_lag_s)
    else:
        coil_t, coil_tdot = housing_t, housing_tdot
    # what the temperature sensor reads: the housing, or the coil through its own lag
    sensor_t = (
        first_order_lag(coil_t, dt, cfg.sensor_lag_s)[0] if cfg.sensor_lag_s > 0 else (housing_t)
    )

    return duration, t_grid, coil_t, coil_tdot, sensor_t


def _vehicle_rotation(cfg: SimulationConfig, t_imu: FloatArray) -> FloatArray | None:
    """The vehicle's true rotation, rad/s (N, 3): 0.5 Hz shaking in the moving phases."""
    if not (cfg.motion_period_s > 0 and cfg.motion_fraction > 0):
        return None
    phase_s = np.mod(t_imu, cfg.motion_period_s)
    moving = phase_s >= (1.0 - cfg.motion_fraction) * cfg.motion_period_s
    amplitude = np.radians(cfg.motion_rate_deg_s)
    rotation = np.zeros((t_imu.size, 3))
    for j in range(3):  # a different phase per axis
        rotation[moving, j] = amplitude * np.sin(2 * np.pi * 0.5 * t_imu[moving] + j)
    return rotation


def simulate_plan(
    cfg: SimulationConfig | None = None,
    *,
    seed: int = 0,
    runs: list[tuple[str, float]] | None = None,
) -> dict[str, SimulatedRun]:
    """Simulate the paper's plan (or ``runs``), run ``k`` with seed ``seed * 1000 + k``.

    The seeds are those of ``fog-temp-comp simulate --seed``, so the runs equal the bags it
    writes with the same configuration.

    Returns
    -------
    dict
        Run name -> :class:`SimulatedRun`, in plan order (training run first).

    """
    plan = runs if runs is not None else paper_plan()
    out = {}
    for k, (kind, setpoint) in enumerate(plan):
        run = simulate_run(kind, setpoint, cfg, seed=seed * 1000 + k)
        out[run.name] = run
    return out
