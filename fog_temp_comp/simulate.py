"""Synthetic thermal-chamber runs of a 3-axis FOG, following the paper's test plan.

Pure numpy: :func:`simulate_run` returns arrays; :mod:`fog_temp_comp.bagio` writes them as bags.

Physics (all documented units):
- chamber air temperature: piecewise-linear profile (cycles at a given degC/min between
  ``low_degC`` and ``high_degC`` with soaks at the ends, or a constant soak with a small
  controller oscillation);
- gyro (coil) temperature: first-order lag of the chamber, time constant ``lag_s``; its exact
  rate ``Tdot = (T_chamber - T_gyro) / lag_s`` drives the drift;
- drift per axis: ``D = d0 + dt*T + dtdot*Tdot`` (deg/h), x near the paper's Table 1;
- gyro noise: angle random walk (white rate) and a Gauss-Markov bias instability;
- temperature sensor: white noise, then quantization (1/16 degC).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from fog_temp_comp.model import PAPER_TERMS, DriftModel, Range
from fog_temp_comp.record import ChamberRecord
from fog_temp_comp.units import RAD_S_PER_DEG_H, S_PER_MIN

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


def true_model() -> DriftModel:
    """The simulator's drift model as a :class:`DriftModel`."""
    return DriftModel(PAPER_TERMS, TRUE_COEFFICIENTS, Range(-60.0, 80.0), Range(-2.0, 2.0))


@dataclass(frozen=True)
class SimulationConfig:
    """Sensor and chamber settings (units in the names)."""

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

    def __post_init__(self) -> None:
        for name in ('imu_hz', 'temp_hz', 'lag_s', 'soak_duration_s'):
            if not getattr(self, name) > 0:
                raise ValueError(f'{name} must be > 0, got {getattr(self, name)}')


@dataclass(frozen=True)
class SimulatedRun:
    """One chamber run.

    Attributes
    ----------
    imu_stamps_s : (N,) ; rates_rad_s : (N, 3) measured gyro output
    temp_stamps_s : (M,) ; temperature_degC : (M,) measured (noisy, quantized) temperature
    true_temperature_degC, true_tdot_degC_per_min : (N,) gyro temperature and rate at imu stamps
    true_drift_deg_h : (N, 3) temperature drift in the gyro output (the part to remove)

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
    """Breakpoints (s from start, degC) of the chamber temperature; linear in between."""
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


def simulate_run(
    kind: str, setpoint: float, cfg: SimulationConfig | None = None, *, seed: int = 0
) -> SimulatedRun:
    """Simulate one run (``kind`` 'cycle' with setpoint in degC/min, or 'soak' in degC)."""
    cfg = cfg or SimulationConfig()
    rng = np.random.default_rng(seed)
    bp_t, bp_x = chamber_profile(kind, setpoint, cfg)
    duration = float(bp_t[-1])
    # 1 s simulation grid for the thermal lag (exact first-order discretisation)
    dt = 1.0
    t_grid = np.arange(0.0, duration + dt, dt)
    chamber = np.interp(t_grid, bp_t, bp_x)
    if kind == 'soak' and cfg.soak_oscillation_degC > 0:
        phase = rng.uniform(0, 2 * np.pi)
        chamber = chamber + cfg.soak_oscillation_degC * np.sin(
            2 * np.pi * t_grid / cfg.soak_oscillation_period_s + phase
        )
    a = np.exp(-dt / cfg.lag_s)
    gyro_t, _ = signal.lfilter([1 - a], [1, -a], chamber, zi=[a * chamber[0]])
    gyro_tdot = (chamber - gyro_t) / cfg.lag_s * S_PER_MIN  # degC/min

    n_imu = int(np.floor(duration * cfg.imu_hz))
    t_imu = np.arange(n_imu) / cfg.imu_hz
    true_t = np.interp(t_imu, t_grid, gyro_t)
    true_tdot = np.interp(t_imu, t_grid, gyro_tdot)
    coeffs = np.asarray(cfg.coefficients, dtype=np.float64)
    drift = np.stack([np.ones_like(true_t), true_t, true_tdot], axis=1) @ coeffs  # (N, 3) deg/h

    sigma_white = cfg.arw_10s_deg_h * np.sqrt(10.0 * cfg.imu_hz)  # per-sample std, deg/h
    white = rng.normal(0.0, sigma_white, size=(n_imu, 3))
    bias = _gauss_markov(
        rng, n_imu, 1.0 / cfg.imu_hz, cfg.bias_instability_deg_h, cfg.bias_correlation_s
    )
    rates = (drift + white + bias) * RAD_S_PER_DEG_H

    n_temp = int(np.floor(duration * cfg.temp_hz))
    t_temp = np.arange(n_temp) / cfg.temp_hz
    temp = np.interp(t_temp, t_grid, gyro_t) + rng.normal(0.0, cfg.temp_noise_degC, n_temp)
    if cfg.temp_quantum_degC > 0:
        temp = np.round(temp / cfg.temp_quantum_degC) * cfg.temp_quantum_degC
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
    )


def _gauss_markov(
    rng: np.random.Generator, n: int, dt_s: float, sigma: float, tau_s: float
) -> FloatArray:
    """First-order Gauss-Markov process, shape (n, 3), stationary std ``sigma``."""
    if sigma <= 0 or n == 0:
        return np.zeros((n, 3))
    phi = np.exp(-dt_s / tau_s)
    drive = rng.normal(0.0, sigma * np.sqrt(1 - phi**2), size=(n, 3))
    drive[0] = rng.normal(0.0, sigma, size=3)
    out, _ = signal.lfilter([1.0], [1.0, -phi], drive, axis=0, zi=np.zeros((1, 3)))
    return out
