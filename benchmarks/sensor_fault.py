"""A temperature sensor stuck at a fault value for minutes: in the training run, in a replayed run.

Run by hand (not in CI)::

    .venv/bin/python benchmarks/sensor_fault.py                         # ~2 min
    .venv/bin/python benchmarks/sensor_fault.py --faults-degC -127 --spell-s 600 --seeds 0 1

The simulator's default chamber (Imu 2 Hz, temperature 1 Hz), seed ``--seeds``: ``calibrate``
with no flags (:func:`fog_temp_comp.core.model_choice.choose_and_calibrate`) on the 0.2
degC/min cycle, clean or with ``--spell-s`` of its readings (40 % into the run) stuck at each
``--faults-degC`` (a connector that opens: -127; a power-on value: 85; an in-range 0); then
the 1 degC/min cycle and the 30 degC soak through the compensator with default guards, clean
or with the same spell. Figures: the 100 s stability after (deg/h, x / y / z) and the largest
error of the corrected rate against the oracle (the raw rate minus the true drift, deg/h, x),
with the oracle's own 100 s stability. Only the defaults are used, so the same script measures
an older checkout side by side (``PYTHONPATH=<worktree>``).
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS
from fog_temp_comp.core.evaluate import compensate_record, score_record
from fog_temp_comp.core.model_choice import choose_and_calibrate
from fog_temp_comp.core.units import RAD_S_PER_DEG_H
from fog_temp_comp.tools.simulate import SimulatedRun, SimulationConfig, simulate_plan

RUNS = [('cycle', 0.2), ('cycle', 1.0), ('soak', 30.0)]


def with_spell(run: SimulatedRun, value_degC: float, spell_s: float) -> SimulatedRun:
    """``run`` with ``spell_s`` of its temperature readings, 40 % into it, at ``value_degC``."""
    t = run.temp_stamps_s
    start = t[0] + 0.4 * (t[-1] - t[0])
    temps = run.temperature_degC.copy()
    temps[(t >= start) & (t < start + spell_s)] = value_degC
    return dataclasses.replace(run, temperature_degC=temps)


def stability_100s(run: SimulatedRun, rates_rad_s: np.ndarray) -> list[float]:
    """The 100 s bias stability of ``rates_rad_s`` (N, 3 rad/s) per axis, deg/h."""
    scores = score_record('c', run.imu_stamps_s, run.rates_rad_s, rates_rad_s, (100.0,))
    return [s.stability_after_deg_h for s in scores]


def figures(run: SimulatedRun, corrected_rad_s: np.ndarray) -> str:
    """'x / y / z' 100 s stability and the largest error against the oracle on x, deg/h."""
    oracle_deg_h = run.rates_rad_s / RAD_S_PER_DEG_H - run.true_drift_deg_h
    error = np.abs(corrected_rad_s[:, 0] / RAD_S_PER_DEG_H - oracle_deg_h[:, 0])
    stab = ' / '.join(f'{v:.4f}' for v in stability_100s(run, corrected_rad_s))
    return f'{stab} | {float(np.nanmax(error)):.3f}'


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seeds', type=int, nargs='+', default=[0])
    parser.add_argument('--faults-degC', type=float, nargs='+', default=[-127.0, 85.0, 0.0])
    parser.add_argument('--spell-s', type=float, default=600.0)
    args = parser.parse_args()
    print(
        '| seed | fault degC | training run | replayed run | run | 100 s x / y / z deg/h | '
        'max error x deg/h |'
    )
    print('|---|---|---|---|---|---|---|')
    for seed in args.seeds:
        runs = simulate_plan(SimulationConfig(imu_hz=2.0), seed=seed, runs=RUNS)
        names = list(runs)
        train, tests = runs[names[0]], [runs[n] for n in names[1:]]
        for run in tests:
            oracle = run.rates_rad_s - run.true_drift_deg_h * RAD_S_PER_DEG_H
            stab = ' / '.join(f'{v:.4f}' for v in stability_100s(run, oracle))
            print(f'| {seed} | - | - | oracle | {run.name} | {stab} | 0 |')
        started = time.perf_counter()
        clean = choose_and_calibrate([train.as_record()], RECOMMENDED_SETTINGS)[0].coefficients
        for run in tests:
            out = compensate_record(run.as_record(), clean)
            print(f'| {seed} | - | clean | clean | {run.name} | {figures(run, out)} |')
        for fault in args.faults_degC:
            hit = with_spell(train, fault, args.spell_s).as_record()
            faulted = choose_and_calibrate([hit], RECOMMENDED_SETTINGS)[0].coefficients
            for run in tests:
                out = compensate_record(run.as_record(), faulted)
                print(f'| {seed} | {fault:g} | spell | clean | {run.name} | {figures(run, out)} |')
            for run in tests:
                spelled = with_spell(run, fault, args.spell_s)
                out = compensate_record(spelled.as_record(), clean)
                print(
                    f'| {seed} | {fault:g} | clean | spell | {run.name} | '
                    f'{figures(spelled, out)} |'
                )
        print(f'(seed {seed}: {time.perf_counter() - started:.0f} s)', flush=True)


if __name__ == '__main__':
    main()
