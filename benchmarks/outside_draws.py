"""The default pipeline on gyros outside the accuracy study's draw ranges.

Run by hand (not in CI)::

    .venv/bin/python benchmarks/outside_draws.py                      # plants 100 and 900
    .venv/bin/python benchmarks/outside_draws.py --plants 103 --variants t_tdot coarse_q

``benchmarks/accuracy.py`` draws its plants from stated ranges; a user's gyro may sit outside
them. Each variant takes a drawn plant (:func:`fog_temp_comp.tools.plants.draw_plant`) and
changes one thing beyond those ranges:

- ``t_tdot``: a Tdot sensitivity that changes with temperature (``T * Tdot``; 0.01-0.02
  deg/h per degC degC/min, i.e. the Tdot coefficient moves by about 1 deg/h/(degC/min) over
  -40..60 degC), which the study never draws;
- ``slow_temp``: temperature at 0.1 Hz;
- ``big_t2``: T^2 of 3e-4 deg/h/degC^2 (5x the study's largest);
- ``coarse_q``: 0.25 degC quantization;
- ``imu10``: gyro at 10 Hz;
- ``noisy_gyro``: 0.1 deg/h 10 s noise (a tactical-grade gyro);
- ``corr_noise``: the temperature sensor's noise correlated over 10 s (an AR(1) of the same
  std: a sensor that averages internally), where the Kalman filters assume white noise;
- ``uneven_steps``: the sensor's quantizer has a differential nonlinearity of 0.5 step (each
  boundary displaced by up to a quarter step: codes 0.5-1.5 steps wide), where the
  quantized likelihood assumes even steps;
- ``temp_20s``: temperature every 20 s (0.05 Hz; a slow housekeeping channel), longer than the
  node's default 10 s staleness timeout;
- ``power_on``: every run, the training run included, starts at power-on and the unit's own
  dissipation warms its housing 5 degC above the air through the housing lag
  (``power_on_heating_degC``); the study's runs start with the unit settled;
- ``t3``: a cubic static drift (``T^3``; 2.5e-6, -2e-6 and 1.2e-6 deg/h/degC^3: an S-shaped
  bias curve), which the study never draws;
- ``bias_step`` and ``bias_kink``: a static drift no low polynomial follows, added to every run:
  0.3, -0.2 and 0.15 deg/h times tanh((T - 20) / 15) (a smooth step), or 0.01, -0.008 and
  0.006 deg/h/degC times max(T - 25, 0) (a change of slope);
- ``axis_lags``: three coils at three places, one sensor: x is the plant's coil, y and z
  follow it through further lags of 150 and 400 s (``axis_coil_lags_s``), so a sensor behind
  x's coil can be ahead of z's; the study's axes share one coil;

three defects of recorded data (the simulated runs changed after the fact):

- ``late_temp``: every run's temperature starts (and stays) 0.7 s after its gyro, as a
  recorder's does;
- ``gyro_bump``: the training run holds one gyro sample 2 deg/s off, 3000 s into it (a touch of
  the turntable);
- ``temp_glitches``: the training run holds three temperature readings of -128 degC (a sensor's
  error code);

and sensors whose driver publishes other than once per conversion:

- ``held_temp``: a 1 Hz sensor published at 10 Hz with the gyro at 10 Hz (a temperature in
  every IMU packet); ``temp_1hz`` is the same sensor published as it converts;
- ``held_slow``: a 0.1 Hz sensor published at 1 Hz (``slow_temp`` published as it converts);
- ``on_change``: the plant's sensor published only when its reading changes (a CAN node, a
  housekeeping channel): minutes between readings at a soak.

The paper's protocol runs on each with default settings (as ``benchmarks/accuracy.py``), and
with the paper's terms for comparison; figures are against the oracle.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from collections.abc import Callable, Sequence

import numpy as np
from accuracy import TRAINING_RUN, add_pipeline_options, metrics, pipeline_settings

from fog_temp_comp.core.calibration import calibrate
from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS
from fog_temp_comp.core.evaluate import compensate_record
from fog_temp_comp.core.model import PAPER_TERMS
from fog_temp_comp.core.model_choice import choose_and_calibrate
from fog_temp_comp.core.units import RAD_S_PER_DEG_H
from fog_temp_comp.tools.plants import draw_plant
from fog_temp_comp.tools.simulate import SimulatedRun, SimulationConfig, simulate_plan

VARIANTS = (
    'base',
    't_tdot',
    'slow_temp',
    'big_t2',
    'coarse_q',
    'imu10',
    'noisy_gyro',
    'corr_noise',
    'uneven_steps',
    'temp_20s',
    'late_temp',
    'gyro_bump',
    'temp_glitches',
    'temp_1hz',
    'held_temp',
    'held_slow',
    'on_change',
    'power_on',
    'axis_lags',
    't3',
    'bias_step',
    'bias_kink',
)

#: the ``power_on`` variant's self-heating, degC above the chamber air
POWER_ON_HEATING_DEGC = 5.0

#: the ``t3`` variant's cubic drift, deg/h/degC^3 (x, y, z): 0.06-0.13 deg/h of it is beyond
#: a quadratic over -40..60 degC
T3_COEFFICIENTS = (2.5e-6, -2e-6, 1.2e-6)

#: static drifts no polynomial of low degree follows, deg/h of the coil's temperature T (degC):
#: (x, y, z) scale and shape
STATIC_SHAPES = {
    'bias_step': ((0.3, -0.2, 0.15), lambda t: np.tanh((t - 20.0) / 15.0)),
    'bias_kink': ((0.01, -0.008, 0.006), lambda t: np.maximum(t - 25.0, 0.0)),
}

#: the ``axis_lags`` variant's further lag of each axis's coil behind the plant's coil, s
AXIS_COIL_LAGS_S = (0.0, 150.0, 400.0)

#: republished temperature: (the sensor's own rate, the rate its last value is published at), Hz
HELD = {'held_temp': (1.0, 10.0), 'held_slow': (0.1, 1.0)}


def variant(name: str, cfg: SimulationConfig) -> SimulationConfig:
    """``cfg`` with one property moved outside the study's draw ranges."""
    changes: dict[str, object] = {
        'base': {},
        't_tdot': {'t_tdot_coefficients': (0.02, -0.015, 0.01)},
        'slow_temp': {'temp_hz': 0.1},
        'big_t2': {'t2_coefficients': tuple(3e-4 * np.sign(v) for v in cfg.t2_coefficients)},
        'coarse_q': {'temp_quantum_degC': 0.25},
        'imu10': {'imu_hz': 10.0},
        'noisy_gyro': {'arw_10s_deg_h': 0.1},
        'corr_noise': {'temp_noise_correlation_s': 10.0},
        'uneven_steps': {'temp_step_nonlinearity': 0.5},
        'temp_20s': {'temp_hz': 0.05},
        'temp_1hz': {'temp_hz': 1.0, 'imu_hz': 10.0},
        'held_temp': {'temp_hz': HELD['held_temp'][0], 'imu_hz': 10.0},
        'held_slow': {'temp_hz': HELD['held_slow'][0]},
        'power_on': {'power_on_heating_degC': POWER_ON_HEATING_DEGC},
        'axis_lags': {'axis_coil_lags_s': AXIS_COIL_LAGS_S},
        't3': {'t3_coefficients': T3_COEFFICIENTS},
    }.get(name, {})
    return dataclasses.replace(cfg, **changes)  # type: ignore[arg-type]


def with_defect(name: str, runs: dict[str, SimulatedRun]) -> dict[str, SimulatedRun]:
    """``runs`` with the recorded-data defect ``name`` (unchanged for the other variants)."""
    if name == 'late_temp':
        return {
            n: dataclasses.replace(r, temp_stamps_s=r.temp_stamps_s + 0.7) for n, r in runs.items()
        }
    if name in HELD:
        return {n: _republished(r, HELD[name][1]) for n, r in runs.items()}
    if name == 'on_change':
        return {n: _on_change(r) for n, r in runs.items()}
    if name in STATIC_SHAPES:
        return {n: _with_static_drift(r, *STATIC_SHAPES[name]) for n, r in runs.items()}
    train = runs[TRAINING_RUN]
    if name == 'gyro_bump':
        rates = train.rates_rad_s.copy()
        rates[int(np.searchsorted(train.imu_stamps_s, train.imu_stamps_s[0] + 3000.0))] += (
            np.deg2rad(2.0)
        )
        return {**runs, TRAINING_RUN: dataclasses.replace(train, rates_rad_s=rates)}
    if name == 'temp_glitches':
        temps = train.temperature_degC.copy()
        temps[np.random.default_rng(3).choice(temps.size, 3, replace=False)] = -128.0
        return {**runs, TRAINING_RUN: dataclasses.replace(train, temperature_degC=temps)}
    return runs


def _with_static_drift(
    run: SimulatedRun, scale_deg_h: tuple[float, float, float], shape: Callable[..., np.ndarray]
) -> SimulatedRun:
    """``run`` with ``scale * shape(T)`` (deg/h, T the coil's degC) in its rate and true drift."""
    extra = np.outer(shape(run.true_temperature_degC), scale_deg_h)
    return dataclasses.replace(
        run,
        rates_rad_s=run.rates_rad_s + extra * RAD_S_PER_DEG_H,
        true_drift_deg_h=run.true_drift_deg_h + extra,
    )


def _republished(run: SimulatedRun, rate_hz: float) -> SimulatedRun:
    """``run`` with its temperature published at ``rate_hz``, each the sensor's latest value."""
    stamps = np.arange(run.temp_stamps_s[0], run.temp_stamps_s[-1], 1.0 / rate_hz)
    latest = np.searchsorted(run.temp_stamps_s, stamps + 1e-9, side='right') - 1
    return dataclasses.replace(
        run, temp_stamps_s=stamps, temperature_degC=run.temperature_degC[latest]
    )


def _on_change(run: SimulatedRun) -> SimulatedRun:
    """``run`` with only the temperature readings that differ from the one before."""
    values = run.temperature_degC
    changed = np.r_[True, values[1:] != values[:-1]]
    return dataclasses.replace(
        run, temp_stamps_s=run.temp_stamps_s[changed], temperature_degC=values[changed]
    )


def study(
    plant: int,
    name: str,
    seed: int = 0,
    hysteresis_quanta: float = 0.0,
    quantized: bool = True,
) -> dict[str, object]:
    """Oracle, default and the paper's terms on one variant of one plant.

    ``hysteresis_quanta``: the default pipeline's ``kalman_hysteresis_quanta`` (README,
    "Readings that toggle between two steps"); ``quantized``: False is ``calibrate
    --gaussian-readings``.
    """
    cfg = variant(name, draw_plant(plant))
    runs = with_defect(name, simulate_plan(cfg, seed=seed))
    held = {n: r for n, r in runs.items() if n != TRAINING_RUN}
    train = [runs[TRAINING_RUN].as_record()]
    rows = {
        'oracle': metrics(
            runs,
            {n: r.rates_rad_s - r.true_drift_deg_h * RAD_S_PER_DEG_H for n, r in held.items()},
        )
    }
    t0 = time.perf_counter()
    settings = pipeline_settings(hysteresis_quanta)
    result, _, chosen = choose_and_calibrate(train, settings, quantized_likelihood=quantized)
    seconds = time.perf_counter() - t0
    coeffs = result.coefficients
    rows['default'] = metrics(
        runs, {n: compensate_record(r.as_record(), coeffs) for n, r in held.items()}
    )
    paper = calibrate(train, RECOMMENDED_SETTINGS, terms=PAPER_TERMS)
    rows['paper terms'] = metrics(
        runs, {n: compensate_record(r.as_record(), paper) for n, r in held.items()}
    )
    return {'rows': rows, 'chosen': chosen.structure.model, 'calibrate_s': seconds}


def main(argv: Sequence[str] | None = None) -> int:
    """Run the variants; print one table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--plants', type=int, nargs='+', default=[100, 900])
    parser.add_argument('--variants', nargs='+', choices=VARIANTS, default=list(VARIANTS))
    add_pipeline_options(parser)
    args = parser.parse_args(argv)
    head = (
        '| plant | variant | chosen | pipeline | 10 s ratio - oracle | 100 s / oracle '
        '| range cycles - oracle | range soaks - oracle |'
    )
    print(head)
    print('|' + '---|' * 8)
    for plant in args.plants:
        for name in args.variants:
            res = study(
                plant,
                name,
                hysteresis_quanta=args.hysteresis_quanta,
                quantized=not args.gaussian_readings,
            )
            rows = res['rows']
            assert isinstance(rows, dict)
            o = rows['oracle']
            for label in ('default', 'paper terms'):
                r = rows[label]
                first = '| | | '
                if label == 'default':
                    first = f'| {plant} | {name} | {res["chosen"]} '
                print(
                    f'{first}| {label} | {r["r10"] - o["r10"]:+.4f} | {r["s100"] / o["s100"]:.2f} '
                    f'| {r["range_cycles"] - o["range_cycles"]:+.3f} '
                    f'| {r["range_soaks"] - o["range_soaks"]:+.3f} |',
                    flush=True,
                )
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
