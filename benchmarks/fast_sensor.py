"""A fast temperature sensor: the default pipeline at 1 and 10 Hz, with and without the refit lag.

Run by hand (not in CI)::

    .venv/bin/python benchmarks/fast_sensor.py                  # seeds 3 and 5, ~6 min
    .venv/bin/python benchmarks/fast_sensor.py --seeds 3 --rates-hz 10
    .venv/bin/python benchmarks/fast_sensor.py --sensor-lag-s 180 --quantum-degC 0.1

The simulator's realistic chamber (:data:`fog_temp_comp.tools.simulate.REALISTIC`: a housing
sensor 180 s ahead of the coil, 1/16 degC steps, 0.02 degC noise, T^2) with Imu at 2 Hz and
the temperature sensor at each rate; ``--sensor-lag-s`` puts the sensor behind the coil
instead (that lag, no coil lag), ``--quantum-degC`` sets its step. ``calibrate`` with no
flags on the 0.2 degC/min cycle (:func:`fog_temp_comp.core.model_choice.choose_and_calibrate`),
then the 1 degC/min cycle through the compensator. Rows: the default, and the default without
the second refinement of the time constant with the quantized-likelihood filter
(:data:`~fog_temp_comp.core.model_choice.QUANTIZED_REFINE_FACTOR` set to 1). Figures: the
100 s stability after (deg/h, per axis), that of the error against the oracle (the raw rate
minus the true drift), and the oracle's.

What it found (session 26): the quantized filter follows a 10 Hz sensor's steps sooner than the
Gaussian one (its Tdot some 20 s earlier), so the coil lag chosen with the Gaussian filter was
too short for it, and 10 Hz came out worse than 1 Hz.
"""

from __future__ import annotations

import argparse
import dataclasses
import multiprocessing
import time

import numpy as np

from fog_temp_comp.core import model_choice
from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS
from fog_temp_comp.core.evaluate import compensate_record, score_record
from fog_temp_comp.core.units import RAD_S_PER_DEG_H
from fog_temp_comp.tools.simulate import REALISTIC, simulate_plan

VARIANTS = ('default', 'no second refinement')
REFINE_FACTOR = model_choice.QUANTIZED_REFINE_FACTOR


def stability_100s_deg_h(run, rates_rad_s: np.ndarray) -> list[float]:
    """The 100 s bias stability of ``rates_rad_s`` per axis, deg/h."""
    scores = score_record('c', run.imu_stamps_s, run.rates_rad_s, rates_rad_s, (100.0,))
    return [s.stability_after_deg_h for s in scores]


def one(job: tuple[int, float, str, float, float]) -> dict[str, object]:
    """Calibrate and compensate one seed at one temperature rate, one variant.

    ``job``: seed, temperature rate (Hz), variant, the sensor's lag behind the coil (s, 0: the
    realistic plant's sensor 180 s ahead) and its step (degC).
    """
    seed, rate_hz, variant, sensor_lag_s, quantum_degC = job
    # a pool's worker runs several jobs: set the factor for each
    model_choice.QUANTIZED_REFINE_FACTOR = REFINE_FACTOR if variant == 'default' else 1.0
    plant = dataclasses.replace(
        REALISTIC, imu_hz=2.0, temp_hz=rate_hz, temp_quantum_degC=quantum_degC
    )
    if sensor_lag_s > 0:
        plant = dataclasses.replace(plant, coil_lag_s=0.0, sensor_lag_s=sensor_lag_s)
    runs = simulate_plan(plant, seed=seed, runs=[('cycle', 0.2), ('cycle', 1.0)])
    t0 = time.perf_counter()
    result, _, chosen = model_choice.choose_and_calibrate(
        [runs['cycle_0p2'].as_record()], RECOMMENDED_SETTINGS
    )
    seconds = time.perf_counter() - t0
    run = runs['cycle_1']
    out = compensate_record(run.as_record(), result.coefficients)
    oracle = run.rates_rad_s - run.true_drift_deg_h * RAD_S_PER_DEG_H
    denoise = result.coefficients.denoise
    return {
        'seed': seed,
        'rate_hz': rate_hz,
        'variant': variant,
        'after': stability_100s_deg_h(run, out),
        'error': stability_100s_deg_h(run, out - oracle),
        'oracle': stability_100s_deg_h(run, oracle),
        'model': chosen.structure.model,
        'lag_s': max(denoise.coil_lag_s, denoise.tdot_lag_s, denoise.sensor_lag_s),
        'calibrate_s': seconds,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--seeds', type=int, nargs='+', default=[3, 5])
    parser.add_argument('--rates-hz', type=float, nargs='+', default=[1.0, 10.0])
    parser.add_argument('--sensor-lag-s', type=float, default=0.0)
    parser.add_argument('--quantum-degC', type=float, default=REALISTIC.temp_quantum_degC)
    args = parser.parse_args()
    jobs = [
        (s, r, v, args.sensor_lag_s, args.quantum_degC)
        for s in args.seeds
        for r in args.rates_hz
        for v in VARIANTS
    ]
    with multiprocessing.get_context('spawn').Pool(2) as pool:
        rows = pool.map(one, jobs)

    def axes(values: object) -> str:
        return ' / '.join(f'{v:.4f}' for v in values)  # type: ignore[attr-defined]

    print(
        '| seed | temperature Hz | pipeline | model | lag s | 100 s after, x / y / z deg/h '
        '| error vs oracle | oracle | calibrate s |'
    )
    print('|---|---|---|---|---|---|---|---|---|')
    for r in rows:
        print(
            f'| {r["seed"]} | {r["rate_hz"]:g} | {r["variant"]} | {r["model"]} | {r["lag_s"]:.0f} '
            f'| {axes(r["after"])} | {axes(r["error"])} | {axes(r["oracle"])} '
            f'| {r["calibrate_s"]:.0f} |'
        )


if __name__ == '__main__':
    main()
