"""Randomly drawn gyros and chambers ("plants") for accuracy studies that no single plant can tune.

:func:`draw_plant` draws a :class:`~fog_temp_comp.tools.simulate.SimulationConfig` from wide ranges
of what real units and chambers do: the temperature sensor ahead of the coil (the coil lags the
housing sensor) or behind it (the sensor reads the coil through its own lag), lags of 0-600 s,
a T^2 drift of either sign, sensor quantization 1/32-0.1 degC and rate 0.2-10 Hz, a chamber
controller with its own period, damping (overshoot) and wobble, and gyro noise of several
grades. The pipeline under test never sees these parameters: it gets the bags only.

Two fixed families of seeds keep the study honest: :data:`TUNING_PLANTS` may be looked at
while developing, :data:`HELDBACK_PLANTS` are only reported.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from fog_temp_comp.tools.simulate import SimulationConfig

#: plant seeds the pipeline may be developed on
TUNING_PLANTS = tuple(range(100, 108))
#: plant seeds never used while developing (reported, not tuned on)
HELDBACK_PLANTS = tuple(range(900, 908))
#: sensor quantization steps drawn from, degC
QUANTA_DEGC = (1.0 / 32.0, 1.0 / 16.0, 0.05, 0.1)


def _loguniform(rng: np.random.Generator, low: float, high: float) -> float:
    return float(np.exp(rng.uniform(np.log(low), np.log(high))))


def draw_plant(seed: int, *, imu_hz: float = 2.0) -> SimulationConfig:
    """One random plant, reproducible from ``seed``.

    Parameters
    ----------
    seed : int
        Plant seed (e.g. from :data:`TUNING_PLANTS` or :data:`HELDBACK_PLANTS`).
    imu_hz : float
        Gyro rate of the simulated runs, Hz.

    Returns
    -------
    SimulationConfig

    """
    rng = np.random.default_rng((seed, 7))
    position = rng.choice(['ahead', 'behind', 'both'], p=[0.4, 0.4, 0.2])
    coil_lag = sensor_lag = 0.0
    if position in ('ahead', 'both'):
        coil_lag = float(rng.uniform(0.0, 600.0))
    if position in ('behind', 'both'):
        sensor_lag = float(rng.uniform(0.0, 600.0))
    sign = rng.choice([-1.0, 1.0], size=3)
    coefficients = np.array(
        [
            rng.uniform(-15.0, 15.0, 3),  # d0_deg_h
            rng.uniform(-5e-3, 5e-3, 3),  # dt_deg_h_per_degC
            sign * rng.uniform(0.2, 1.5, 3),  # dtdot_deg_h_per_degC_per_min
        ]
    )
    t2 = rng.choice([-1.0, 1.0], size=3) * np.array(
        [_loguniform(rng, 1e-6, 6e-5) for _ in range(3)]
    )
    fields: dict[str, Any] = dict(
        imu_hz=imu_hz,
        temp_hz=_loguniform(rng, 0.2, 10.0),
        lag_s=float(rng.uniform(300.0, 1200.0)),
        coil_lag_s=coil_lag,
        sensor_lag_s=sensor_lag,
        chamber_period_s=float(rng.uniform(300.0, 1500.0)),
        chamber_damping=float(rng.uniform(0.3, 1.0)),
        soak_oscillation_degC=float(rng.uniform(0.05, 0.5)),
        soak_oscillation_period_s=float(rng.uniform(600.0, 2400.0)),
        cycle_oscillation_degC=float(rng.uniform(0.0, 0.2)),
        temp_quantum_degC=float(rng.choice(QUANTA_DEGC)),
        temp_noise_degC=_loguniform(rng, 0.002, 0.03),
        arw_10s_deg_h=_loguniform(rng, 0.008, 0.04),
        bias_instability_deg_h=_loguniform(rng, 0.002, 0.01),
        bias_random_walk_deg_h_per_sqrt_h=_loguniform(rng, 0.0005, 0.005),
        coefficients=coefficients,
        t2_coefficients=tuple(float(v) for v in t2),
    )
    return SimulationConfig(**fields)


def describe(cfg: SimulationConfig) -> dict[str, float | str]:
    """The plant parameters a study table shows (units in the keys)."""
    data = dataclasses.asdict(cfg)
    position = (
        'both'
        if cfg.coil_lag_s and cfg.sensor_lag_s
        else 'behind'
        if cfg.sensor_lag_s
        else 'ahead'
    )
    return {
        'sensor': position,
        'coil_lag_s': round(cfg.coil_lag_s),
        'sensor_lag_s': round(cfg.sensor_lag_s),
        'temp_hz': round(cfg.temp_hz, 2),
        'quantum_degC': round(cfg.temp_quantum_degC, 4),
        'temp_noise_degC': round(cfg.temp_noise_degC, 4),
        'max_abs_t2': float(np.max(np.abs(data['t2_coefficients']))),
        'chamber_damping': round(cfg.chamber_damping, 2),
    }
