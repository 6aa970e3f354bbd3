"""Messages lost by the sensor, the driver or DDS: what each loss pattern costs the correction.

Run by hand (not in CI)::

    .venv/bin/python benchmarks/message_loss.py                      # ~9 min
    .venv/bin/python benchmarks/message_loss.py --plants 100 --patterns 'temp 5 %' 'temp 1 in 3'

The simulator never loses a message; real sensors and DDS do. Per plant (``default``: the
simulator's default chamber, Imu 2 Hz, temperature 1 Hz; a number: a drawn plant of the
accuracy study, :func:`fog_temp_comp.tools.plants.draw_plant`), seed 0: the 0.2 degC/min cycle
(training), the 1 and 0.5 degC/min cycles and the -40 degC soak (replayed). Each loss pattern
(:data:`PATTERNS`: temperature readings lost i.i.d., every third one, in bursts; gyro messages
lost i.i.d.; both) removes messages with a fixed seed per pattern and run, in two scenarios:

- ``a``: the replayed runs lose them; ``calibrate`` (no flags) on the clean training run;
- ``b``: the training run loses them too (a chamber bag that lost messages), and ``calibrate``
  with no flags on it (:func:`~fog_temp_comp.core.model_choice.choose_and_calibrate`).

Figures as in ``accuracy.py`` (its :func:`metrics`): the median over runs and axes of the
10 s stability ratio after/before, the median 100 s stability after (deg/h) and the worst 10 s
range ratio on the cycles and on the soak, each as ``lossy / clean / oracle``: the pipeline on
the lossy runs, the clean pipeline (calibrated and replayed without loss) and the oracle (the
raw rate minus the true drift), all three on the same gyro messages: those the loss kept and
the lossy compensator published (it drops those awaiting the first reading), so that their
10 s windows fall alike. ``100 s: lossy over clean`` is what the loss costs the pipeline
beyond the messages themselves (a lost gyro message costs the compensator nothing else: its
correction depends on the temperature only); ``oracle 100 s: kept over all``, what the lost
gyro messages cost any method (the oracle on the kept messages over the oracle on all).
``model``: what ``calibrate`` chose in scenario ``b`` (``=``: the clean choice; the time
constants are fitted values, shown apart). ``counters``: the compensator's non-zero counters,
summed over the replayed runs, but for those the clean replay has too
(:data:`ROUTINE_COUNTERS`), the gyro's as a share of the gyro messages. ``temp 33 %`` is there
to set beside ``temp 1 in 3`` (the same share, lost at random and periodically). The model
choice runs in one process (``FOG_TEMP_COMP_PROCESSES=1`` unless set otherwise).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time
import zlib
from collections.abc import Callable

import numpy as np
from accuracy import metrics
from numpy.typing import NDArray

from fog_temp_comp.core.coefficients import Coefficients
from fog_temp_comp.core.compensator_types import CompensatorCounters
from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS
from fog_temp_comp.core.evaluate import replay_record
from fog_temp_comp.core.forked import ONE_PROCESS_VARIABLE
from fog_temp_comp.core.model_choice import choose_and_calibrate
from fog_temp_comp.core.units import RAD_S_PER_DEG_H
from fog_temp_comp.tools.plants import draw_plant
from fog_temp_comp.tools.simulate import SimulatedRun, SimulationConfig, simulate_plan

Mask = NDArray[np.bool_]
#: a loss pattern: the kept messages (True) of a stream of n, from a generator
Loss = Callable[[int, np.random.Generator], Mask]

RUNS = [('cycle', 0.2), ('cycle', 1.0), ('cycle', 0.5), ('soak', -40.0)]
#: the loss patterns' seed, with the pattern's name and the run's index
LOSS_SEED = 36
#: counters that the clean replay has too (not reported)
ROUTINE_COUNTERS = (
    'imu_corrected',
    'temperature_accepted',
    'imu_temperature_clamped',
    'imu_tdot_clamped',
    'imu_tdot_extrapolated',
)
#: bursts of lost readings: this fraction of the readings, in bursts of this many (inclusive)
BURST_FRACTION = 0.10
BURST_READINGS = (5, 30)


def keep_all(n: int, rng: np.random.Generator) -> Mask:
    """No loss."""
    return np.ones(n, dtype=bool)


def iid(fraction: float) -> Loss:
    """Each message lost with probability ``fraction``, independently."""

    def loss(n: int, rng: np.random.Generator) -> Mask:
        return rng.random(n) >= fraction

    return loss


def every_third(n: int, rng: np.random.Generator) -> Mask:
    """Every third message lost (the 3rd, 6th, ...): the readings' intervals alternate 1, 2."""
    return np.arange(n) % 3 != 2


def bursts(n: int, rng: np.random.Generator) -> Mask:
    """:data:`BURST_FRACTION` of the messages lost in bursts of :data:`BURST_READINGS`.

    Bursts of a uniform length, the kept stretches between them exponential with the mean
    that makes the fraction lost :data:`BURST_FRACTION` on average.
    """
    low, high = BURST_READINGS
    mean_kept = (low + high) / 2 * (1 - BURST_FRACTION) / BURST_FRACTION
    keep = np.ones(n, dtype=bool)
    i = int(rng.exponential(mean_kept))
    while i < n:
        length = int(rng.integers(low, high + 1))
        keep[i : i + length] = False
        i += length + 1 + int(rng.exponential(mean_kept))
    return keep


#: name -> (temperature loss, gyro loss)
PATTERNS: dict[str, tuple[Loss, Loss]] = {
    'temp 5 %': (iid(0.05), keep_all),
    'temp 20 %': (iid(0.20), keep_all),
    'temp 33 %': (iid(1 / 3), keep_all),
    'temp 50 %': (iid(0.50), keep_all),
    'temp 1 in 3': (every_third, keep_all),
    'temp bursts 10 %': (bursts, keep_all),
    'imu 5 %': (keep_all, iid(0.05)),
    'imu 20 %': (keep_all, iid(0.20)),
    'both 20 %': (iid(0.20), iid(0.20)),
}


def kept(run: SimulatedRun, pattern: str, index: int) -> tuple[Mask, Mask]:
    """The gyro messages and the temperature readings of ``run`` that ``pattern`` keeps.

    ``index``: the run's place in the plan (0: training), which seeds the loss with the pattern.
    """
    temp_loss, imu_loss = PATTERNS[pattern]
    seed = (LOSS_SEED, zlib.crc32(pattern.encode()), index)
    temp = temp_loss(run.temp_stamps_s.size, np.random.default_rng((*seed, 0)))
    imu = imu_loss(run.imu_stamps_s.size, np.random.default_rng((*seed, 1)))
    return imu, temp


def lossy(run: SimulatedRun, pattern: str, index: int) -> SimulatedRun:
    """``run`` (the ``index``-th of the plan) without the messages ``pattern`` loses."""
    return run.select(*kept(run, pattern, index))


def oracle_rad_s(run: SimulatedRun) -> np.ndarray:
    """The raw rate minus the true drift (the best any method can do), (N, 3) rad/s."""
    return run.rates_rad_s - run.true_drift_deg_h * RAD_S_PER_DEG_H


def replayed(
    runs: dict[str, SimulatedRun], coeffs: Coefficients
) -> tuple[dict[str, np.ndarray], dict[str, int]]:
    """The compensator's output (N, 3) rad/s on each of ``runs``, and its counters summed."""
    corrected = {}
    total: dict[str, int] = {}
    for name, run in runs.items():
        corrected[name], status = replay_record(run.as_record(), coeffs)
        for key, value in dataclasses.asdict(status.counters).items():
            total[key] = total.get(key, 0) + int(value)
    return corrected, total


def scored_alike(
    runs: dict[str, SimulatedRun],
    imu_kept: dict[str, Mask],
    lossy_rad_s: dict[str, np.ndarray],
    clean_rad_s: dict[str, np.ndarray],
) -> tuple[dict[str, float], dict[str, float], dict[str, float]]:
    """The figures of the lossy pipeline, the clean one and the oracle on the same messages.

    ``runs``: the clean runs; ``imu_kept``: their gyro messages the loss kept, each with a
    row of ``lossy_rad_s``; ``clean_rad_s``: the clean pipeline's output on every message.
    All three are scored on the kept messages the lossy pipeline published (not those it
    dropped awaiting the first reading), so that their 10 s windows fall alike.
    """
    scored, lossy_out, clean_out = {}, {}, {}
    for name, run in runs.items():
        published = np.isfinite(lossy_rad_s[name]).all(axis=1)
        rows = imu_kept[name].copy()
        rows[np.flatnonzero(rows)[~published]] = False
        scored[name] = run.select(rows, np.ones(run.temp_stamps_s.size, dtype=bool))
        lossy_out[name] = lossy_rad_s[name][published]
        clean_out[name] = clean_rad_s[name][rows]
    orc = {n: oracle_rad_s(r) for n, r in scored.items()}
    return metrics(scored, lossy_out), metrics(scored, clean_out), metrics(scored, orc)


def calibrated(train: SimulatedRun) -> tuple[Coefficients, str, str]:
    """``calibrate`` with no flags on one run: the coefficients, the model and its time constants.

    The model: terms, lags modelled, the Kalman walk and shrinkage, the fit, ``QL`` with the
    quantized likelihood; the time constants (coil, sensor and Tdot lags, s) are fitted values.
    """
    result, _, chosen = choose_and_calibrate([train.as_record()], RECOMMENDED_SETTINGS)
    coeffs, s = result.coefficients, chosen.structure
    quantized = ' QL' if coeffs.denoise.kalman_quantized_noise_degC > 0 else ''
    model = f'{s.model} (walk {s.walk:g}, shrink {s.shrink_sigmas:g}, {s.fit}{quantized})'
    lags = [
        f'{name} {value:.0f} s'
        for name, value in (
            ('coil', coeffs.denoise.coil_lag_s),
            ('sensor', coeffs.denoise.sensor_lag_s),
            ('Tdot_lag', coeffs.denoise.tdot_lag_s),
        )
        if value
    ]
    return coeffs, model, ', '.join(lags)


def model_text(model: str, lags: str) -> str:
    """The model and its fitted time constants, for the table."""
    return f'{model}; {lags}' if lags else model


def counter_text(counters: dict[str, int]) -> str:
    """The counters worth reading: non-zero, not the routine ones; the gyro's as a % of all."""
    imu_total = CompensatorCounters(
        **{k: v for k, v in counters.items() if k in CompensatorCounters.__dataclass_fields__}
    ).imu_total
    parts = []
    for key, value in counters.items():
        if value and key not in ROUTINE_COUNTERS:
            share = f' ({100 * value / imu_total:.2f} %)' if key.startswith('imu_') else ''
            parts.append(f'{key} {value}{share}')
    return ', '.join(parts) or '-'


#: the figures of :func:`accuracy.metrics` and their format
FIGURES = (('r10', '.4f'), ('s100', '.4f'), ('range_cycles', '.3f'), ('range_soaks', '.3f'))


def cells(pipeline: dict[str, float], clean: dict[str, float], orc: dict[str, float]) -> str:
    """Markdown cells: each figure as lossy / clean / oracle."""
    return ' | '.join(
        f'{pipeline[k]:{fmt}} / {clean[k]:{fmt}} / {orc[k]:{fmt}}' for k, fmt in FIGURES
    )


def growth_percent(lossy_s100_deg_h: float, clean_s100_deg_h: float) -> str:
    """How much larger the lossy run's 100 s stability is than the clean one's, %."""
    return f'{100.0 * (lossy_s100_deg_h / clean_s100_deg_h - 1.0):+.1f} %'


def plant_config(plant: str) -> SimulationConfig:
    """``default`` (the simulator's chamber, Imu 2 Hz) or a drawn plant's number."""
    return SimulationConfig(imu_hz=2.0) if plant == 'default' else draw_plant(int(plant))


@dataclasses.dataclass
class Baseline:
    """One plant's clean pipeline: the runs, the default calibration and its clean figures."""

    train: SimulatedRun
    tests: dict[str, SimulatedRun]  # the replayed runs by name
    coeffs: Coefficients
    model: str
    lags: str
    clean_rad_s: dict[str, np.ndarray]  # each replayed run's corrected rates
    clean_counters: dict[str, int]
    every: dict[str, Mask]  # every gyro message of each replayed run
    clean: dict[str, float]  # the clean replay's figures
    clean_oracle: dict[str, float]  # the oracle's on the same messages


def baseline(plant: str) -> Baseline:
    """Simulate ``plant``'s plan (seed 0), calibrate on its training run, replay the others."""
    runs = list(simulate_plan(plant_config(plant), seed=0, runs=RUNS).values())
    train, tests = runs[0], {r.name: r for r in runs[1:]}
    coeffs, model, lags = calibrated(train)
    clean_rad_s, clean_counters = replayed(tests, coeffs)
    every = {n: np.ones(r.imu_stamps_s.size, dtype=bool) for n, r in tests.items()}
    clean, _, clean_oracle = scored_alike(tests, every, clean_rad_s, clean_rad_s)
    return Baseline(
        train, tests, coeffs, model, lags, clean_rad_s, clean_counters, every, clean, clean_oracle
    )


def run_study(
    study: Callable[[str, list[str], list[str]], None],
    header: str,
    plants: list[str],
    cases: list[str],
    scenarios: list[str],
) -> None:
    """Print ``header`` (table columns), then ``study``'s rows of each plant, in one process."""
    os.environ.setdefault(ONE_PROCESS_VARIABLE, '1')
    print(header)
    print('|---' * header.count('|', 1) + '|')
    started = time.perf_counter()
    for plant in plants:
        study(plant, cases, scenarios)
    print(f'(total {time.perf_counter() - started:.0f} s)', flush=True)


def study_plant(plant: str, patterns: list[str], scenarios: list[str]) -> None:
    """Print the rows of one plant: clean, then each pattern and scenario."""
    started = time.perf_counter()
    base = baseline(plant)
    train, tests, coeffs, model = base.train, base.tests, base.coeffs, base.model
    clean_rad_s, clean_oracle = base.clean_rad_s, base.clean_oracle
    print(
        f'| {plant} | none | - | {model_text(model, base.lags)} '
        f'| {cells(base.clean, base.clean, clean_oracle)} | - | - '
        f'| {counter_text(base.clean_counters)} |',
        flush=True,
    )
    for pattern in patterns:
        masks = {n: kept(r, pattern, k + 1) for k, (n, r) in enumerate(tests.items())}
        lost = {n: r.select(*masks[n]) for n, r in tests.items()}
        imu_kept = {n: m[0] for n, m in masks.items()}
        for scenario in scenarios:
            used, name = coeffs, '='
            if scenario == 'b':
                used, chosen, chosen_lags = calibrated(lossy(train, pattern, 0))
                name = model_text('=' if chosen == model else chosen, chosen_lags)
            lossy_rad_s, counters = replayed(lost, used)
            figures, alike, orc = scored_alike(tests, imu_kept, lossy_rad_s, clean_rad_s)
            print(
                f'| {plant} | {pattern} | {scenario} | {name} | {cells(figures, alike, orc)} '
                f'| {growth_percent(figures["s100"], alike["s100"])} '
                f'| {growth_percent(orc["s100"], clean_oracle["s100"])} '
                f'| {counter_text(counters)} |',
                flush=True,
            )
    print(f'(plant {plant}: {time.perf_counter() - started:.0f} s)', flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--plants', nargs='+', default=['100', '105', '900'])
    parser.add_argument('--patterns', nargs='+', choices=list(PATTERNS), default=list(PATTERNS))
    parser.add_argument('--scenarios', nargs='+', choices=('a', 'b'), default=['a', 'b'])
    args = parser.parse_args()
    header = (
        '| plant | loss | scenario | model | 10 s ratio: lossy / clean / oracle '
        '| 100 s deg/h | range cycles | range soaks | 100 s: lossy over clean '
        '| oracle 100 s: kept over all | counters |'
    )
    run_study(study_plant, header, args.plants, args.patterns, args.scenarios)


if __name__ == '__main__':
    main()
