"""Side study: a Kalman filter that knows the sensor lags the coil, its lag chosen from the data.

Run by hand (not in CI)::

    .venv/bin/python benchmarks/sensor_lag_kalman.py                 # tuning plants, sensor behind
    .venv/bin/python benchmarks/sensor_lag_kalman.py --plants 900 905 --seed 1

The default pipeline estimates the *sensor's* temperature and Tdot (Kalman on
[T, Tdot]) and reaches the coil through a fitted lead-lag (``Tdot_lag``). Where the sensor
lags the coil, a filter on the states [T_coil, Tdot_coil, T_sensor] with the sensor a
first-order lag of the coil (:mod:`causal_floor`'s model) estimates the coil's Tdot directly,
with the noise trade-off of the Kalman filter rather than a lead fitted on the ramps.

Here the filter's two unknowns are chosen the way ``calibrate`` would have to: the sensor's
time constant on a grid of 0-720 s and the bandwidth (time scale 30/60/120 s) by the training
run's own score (geometric mean of the 10 s and 100 s stability ratios of the fit's residual,
in sample: every candidate has the same terms), then the paper's terms plus ``T2`` are fitted
by least squares on ``cycle_0p2`` and the held-out runs are scored against the oracle as in
:mod:`accuracy`. Tdot gets the same Wiener gain as the package's default (600 s, the filter's
posterior standard deviation). The measurement noise is the plant's (``calibrate`` measures
it). The steady-state filter is used (``scipy.signal.lfilter``); an online version would be
the time-varying filter, equal after its warm-up.

Printed: per plant, the chosen time constant and bandwidth and the study's four figures
against the oracle (10 s ratio less the oracle's, 100 s / oracle, worst ranges less the
oracle's), for this filter and for the package's default.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy import linalg

sys.path.insert(0, str(Path(__file__).resolve().parent))

from accuracy import TRAINING_RUN, metrics
from causal_floor import behind_plants_cli, coil_estimates, sensor_behind_model

from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS
from fog_temp_comp.core.evaluate import compensate_record
from fog_temp_comp.core.grid import bin_means
from fog_temp_comp.core.model import design_matrix
from fog_temp_comp.core.model_choice import choose_and_calibrate
from fog_temp_comp.core.tdot_wiener import wiener_gains
from fog_temp_comp.core.units import DEG_H_PER_RAD_S, RAD_S_PER_DEG_H, S_PER_MIN
from fog_temp_comp.tools.plants import draw_plant
from fog_temp_comp.tools.simulate import SimulatedRun, simulate_plan

TERMS = ('const', 'T', 'Tdot', 'T2')
#: sensor time constants tried, s (1 s: no lag to speak of)
SENSOR_LAGS_S = (1.0, 60.0, 120.0, 240.0, 360.0, 480.0, 720.0)
#: Kalman bandwidths tried, s
TIME_SCALES_S = (30.0, 60.0, 120.0)
WIENER_WINDOW_S = 600.0


def coil_inputs(
    run: SimulatedRun, time_scale_s: float, r: float, tau_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """Coil T (degC) and Wiener-gained Tdot (degC/min) at the gyro stamps."""
    temperature, tdot = coil_estimates(run, time_scale_s, r, tau_s)
    dt = float(np.median(np.diff(run.temp_stamps_s)))
    f, h, q = sensor_behind_model(dt, r * dt * time_scale_s**-4.0, tau_s)
    p = linalg.solve_discrete_are(f.T, h.T, q, np.atleast_2d(r))
    k = p @ h.T / (float((h @ p @ h.T)[0, 0]) + r)
    std = float(np.sqrt(((np.eye(3) - k @ h) @ p)[1, 1])) * S_PER_MIN
    gains = wiener_gains(run.imu_stamps_s, tdot, np.full_like(tdot, std), WIENER_WINDOW_S)
    return temperature, tdot * gains


def in_sample_score(residual: np.ndarray, rate: np.ndarray) -> float:
    """Geometric mean over axes of the 10 s and 100 s stability ratios, on 10 s bins (M, 3)."""

    def stability(v: np.ndarray, k: int) -> np.ndarray:
        return v[: v.shape[0] // k * k].reshape(-1, k, 3).mean(axis=1).std(axis=0)

    ratios = [stability(residual, k) / stability(rate, k) for k in (1, 10)]
    return float(np.exp(np.mean(np.log(np.concatenate(ratios)))))


def study(plant: int, seed: int) -> list[str]:
    cfg = draw_plant(plant)
    runs = simulate_plan(cfg, seed=seed)
    held = {n: r for n, r in runs.items() if n != TRAINING_RUN}
    oracle = metrics(
        runs, {n: r.rates_rad_s - r.true_drift_deg_h * RAD_S_PER_DEG_H for n, r in held.items()}
    )
    r = cfg.temp_noise_degC**2 + cfg.temp_quantum_degC**2 / 12.0
    train = runs[TRAINING_RUN]
    _, _, rate = bin_means(train.imu_stamps_s, train.rates_rad_s * DEG_H_PER_RAD_S, 10.0)
    best: tuple[float, float, float, np.ndarray] | None = None
    for tau in SENSOR_LAGS_S:
        for scale in TIME_SCALES_S:
            x = design_matrix(*coil_inputs(train, scale, r, tau), TERMS)
            _, _, xb = bin_means(train.imu_stamps_s, x, 10.0)
            coef = np.linalg.lstsq(xb, rate, rcond=None)[0]
            score = in_sample_score(rate - xb @ coef, rate)
            if best is None or score < best[0]:
                best = (score, tau, scale, coef)
    assert best is not None
    _, tau, scale, coef = best
    lagged = metrics(
        runs,
        {
            n: run.rates_rad_s
            - design_matrix(*coil_inputs(run, scale, r, tau), TERMS) @ coef * RAD_S_PER_DEG_H
            for n, run in held.items()
        },
    )
    result, _, _ = choose_and_calibrate([train.as_record()], RECOMMENDED_SETTINGS)
    default = metrics(
        runs, {n: compensate_record(r.as_record(), result.coefficients) for n, r in held.items()}
    )

    def row(name: str, m: dict[str, float]) -> str:
        return (
            f'| {name} | {m["r10"] - oracle["r10"]:+.4f} | {m["s100"] / oracle["s100"]:.2f} '
            f'| {m["range_cycles"] - oracle["range_cycles"]:+.3f} '
            f'| {m["range_soaks"] - oracle["range_soaks"]:+.3f} |'
        )

    head = f'| {plant} | {seed} | {cfg.sensor_lag_s:.0f} | {tau:g} | {scale:g} '
    return [head + row('sensor-lag Kalman', lagged), '| | | | | ' + row('default', default)]


def main(argv: list[str] | None = None) -> int:
    header = (
        '| plant | seed | true sensor lag s | chosen lag s | time scale s | pipeline '
        '| 10 s ratio - oracle | 100 s / oracle | range cycles - oracle | range soaks - oracle |'
    )
    return behind_plants_cli(argv, __doc__.split('\n')[0], header, study)


if __name__ == '__main__':
    raise SystemExit(main())
