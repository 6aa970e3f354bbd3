"""Tdot errors of the Kalman filters with Gaussian readings and with the quantized likelihood.

Run by hand (not in CI)::

    .venv/bin/python benchmarks/quantized_likelihood.py                   # 5 plants
    .venv/bin/python benchmarks/quantized_likelihood.py --plants 904 102

The Gaussian filters take a reading ``y`` for ``T + v``, ``v`` white of variance ``noise^2 +
quantum^2 / 12``, averaged over 0.5 s cells. For a quiet sensor (noise well under a step) that
is wrong where the temperature hovers at a step boundary: the readings toggle, and their mean
sweeps across a step while the temperature barely moves. The quantized-likelihood filters
(:mod:`fog_temp_comp.core.tdot_kalman_quantized`, ``calibrate``'s default for a quantized
sensor) take each raw reading for what it says: ``y - q/2 <= T + e < y + q/2``.

Per plant (seed 0): the coil-Tdot RMS error and the std of its 100 s means after the first
30 min on four runs, for the sensor-lag filter with Gaussian readings (the plant's true lag,
the noise ``calibrate`` measures by moments) and with the quantized likelihood (the same lag
and walk, the noise fitted by likelihood, :mod:`fog_temp_comp.core.quantized_noise_fit`). The
whole pipeline's comparison is ``benchmarks/accuracy.py`` against ``benchmarks/accuracy.py
--gaussian-readings``.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections.abc import Sequence

import numpy as np

from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.quantized_noise_fit import fit_quantized_noise
from fog_temp_comp.core.sensor_noise import sensor_noise
from fog_temp_comp.core.tdot import kalman_estimator

RUNS = ('cycle_0p2', 'cycle_1', 'soak_m40', 'soak_30')


def score(
    stamps: np.ndarray, tdot: np.ndarray, truth_t: np.ndarray, truth: np.ndarray
) -> tuple[float, float]:
    """RMS error and std of 100 s means of the error after 30 min, degC/min."""
    err = tdot - np.interp(stamps, truth_t, truth)
    keep = stamps > stamps[0] + 1800.0
    err, ts = err[keep], stamps[keep]
    k = ((ts - ts[0]) // 100.0).astype(int)
    means = np.bincount(k, err) / np.bincount(k)
    return float(np.sqrt(np.mean(err**2))), float(means.std())


def compare_plant(plant: int) -> str:
    """The table row of one plant: Gaussian readings against the quantized likelihood."""
    from fog_temp_comp.tools.plants import draw_plant
    from fog_temp_comp.tools.simulate import simulate_plan

    cfg = draw_plant(plant)
    runs = simulate_plan(cfg, seed=0)
    train = runs['cycle_0p2'].as_record()
    measured = sensor_noise([train])
    fit = fit_quantized_noise([train], measured.quantum_degC)
    gaussian = measured.apply(
        DenoiseSettings(
            method='kalman',
            kalman_rate_walk_degC_per_min_per_sqrt_s=0.001,
            sensor_lag_s=cfg.sensor_lag_s,
            kalman_repeat_rate_degC_per_min=0.1,
        )
    )
    quantized = dataclasses.replace(gaussian, kalman_quantized_noise_degC=fit.noise_degC)
    row = (
        f'| {plant} | {cfg.temp_noise_degC / cfg.temp_quantum_degC:.2f} | '
        f'{measured.noise_degC:.4f} | {fit.noise_degC:.4f} |'
    )
    for name in RUNS:
        r = runs[name]
        cells = []
        for settings in (gaussian, quantized):
            e = kalman_estimator(settings).add_series(r.temp_stamps_s, r.temperature_degC)
            rms, std100 = score(
                e.stamp_s, e.tdot_degC_per_min, r.imu_stamps_s, r.true_tdot_degC_per_min
            )
            cells.append(f'{rms:.4f} ({std100:.4f})')
        row += f' {cells[0]} / {cells[1]} |'
    return row


def main(argv: Sequence[str] | None = None) -> int:
    """Print the comparison table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--plants', type=int, nargs='+', default=[102, 904, 907, 905, 100])
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    print(
        '| plant | true noise / quantum | noise by moments, degC | noise by likelihood, degC | '
        + ' | '.join(f'{n}: Tdot RMS (100 s std), Gaussian / quantized' for n in RUNS)
        + ' |'
    )
    print('|' + '---|' * (4 + len(RUNS)))
    for plant in args.plants:
        print(compare_plant(plant), flush=True)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
