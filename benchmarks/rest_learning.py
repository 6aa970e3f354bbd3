"""Bias learning at rest on simulated runs with a turn-on shift: error against the oracle.

Each run is the simulator's 0.5 degC/min cycle between 10 and 30 degC (10 Hz gyro, 2.3 h) with
a turn-on shift of (3, -2, 1.5) deg/h that calibration never saw, and vehicle phases:

- ``rest+motion``: every 10 min the unit rests 5 min, then shakes (5 deg/s, 0.5 Hz) for 5 min;
- ``moving``: it shakes all the time (no rest: learning must change nothing);
- ``chamber``: it never moves.

The drift model is the simulator's true one (Kalman Tdot), so what remains is the shift and
the sensor noise. The error is the corrected rate minus the vehicle's rotation (the oracle).
Columns: mean error over the run after the Tdot filter's warm-up and over its last hour (deg/h,
per axis), and the 10 s and 100 s stability (std of window means, deg/h, worst axis).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from benchutil import machine, table

from fog_temp_comp.core.compensator import Compensator, replay
from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.metrics import bias_stability, window_means
from fog_temp_comp.core.rest import RestSettings
from fog_temp_comp.core.units import DEG_H_PER_RAD_S
from fog_temp_comp.tools.simulate import SimulationConfig, simulate_run, true_model

SHIFT_DEG_H = (3.0, -2.0, 1.5)
BASE = SimulationConfig(
    imu_hz=10.0,
    low_degC=10.0,
    high_degC=30.0,
    start_degC=20.0,
    cycle_soak_s=600.0,
    soak_duration_s=1800.0,
    turn_on_shift_deg_h=SHIFT_DEG_H,
)
SCENARIOS = {
    'rest+motion': dataclasses.replace(BASE, motion_period_s=600.0, motion_fraction=0.5),
    'moving': dataclasses.replace(BASE, motion_period_s=600.0, motion_fraction=1.0),
    'chamber': BASE,
}
WARM_UP_S = 300.0


def vec(v: np.ndarray) -> str:
    return ', '.join(f'{x:+.3f}' for x in v)


def main() -> None:
    print(f'# rest_learning: turn-on shift {SHIFT_DEG_H} deg/h; {machine()}')
    rows = []
    for name, cfg in SCENARIOS.items():
        run = simulate_run('cycle', 0.5, cfg, seed=5)
        t = run.imu_stamps_s
        for learn in (False, True):
            rest = RestSettings(enabled=learn)
            comp = Compensator(true_model(cfg), DenoiseSettings(method='kalman'), rest=rest)
            out = replay(comp, t, run.rates_rad_s, run.temp_stamps_s, run.temperature_degC)
            err = run.oracle_error_rad_s(out) * DEG_H_PER_RAD_S
            keep = t >= t[0] + WARM_UP_S
            last = t >= t[-1] - 3600.0
            s10 = bias_stability(window_means(t[keep], err[keep], 10.0)).max()
            s100 = bias_stability(window_means(t[keep], err[keep], 100.0)).max()
            windows = '-' if comp.rest is None else str(comp.rest.status.windows_rest)
            rows.append(
                [
                    name,
                    'on' if learn else 'off',
                    windows,
                    vec(err[keep].mean(axis=0)),
                    vec(err[last].mean(axis=0)),
                    f'{s10:.3f}',
                    f'{s100:.3f}',
                ]
            )
    headers = [
        'run',
        'learning',
        'rest windows',
        'mean error deg/h',
        'last hour deg/h',
        '10 s stab.',
        '100 s stab.',
    ]
    print(table(headers, rows))


if __name__ == '__main__':
    main()
