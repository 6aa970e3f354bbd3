"""Temperature readings lost for a while in a replayed run: bridged by the Kalman filter or not.

Run by hand (not in CI)::

    .venv/bin/python benchmarks/temperature_gap.py                    # ~12 min
    .venv/bin/python benchmarks/temperature_gap.py --plants 100 --gaps-s 900 1800 --bridge-s 1e6

A driver that restarts, a serial line that drops, a sensor fault that the node rejects: the
temperature stops for a while and comes back. Per plant (``default``: the simulator's default
chamber, Imu 2 Hz, temperature 1 Hz; a number: a drawn plant of the accuracy study,
:func:`fog_temp_comp.tools.plants.draw_plant`), seed 0: ``calibrate`` with no flags on the
0.2 degC/min cycle, then the 1 and 0.5 degC/min cycles through the compensator, clean and with
the readings of ``--gaps-s`` removed at each of 9 places (10 % ... 90 % into the run). Each
gap is replayed with the default guards (the Kalman filter bridges a gap up to
``temperature_bridge_s``, 1800 s) and with ``temperature_bridge_s`` 0 (every gap restarts the
estimate, as before session 29). Figures: the 10 s range and the 100 s stability after, each
over the clean run's (per axis and place: the median and the largest), so 1.000 is a gap that
costs nothing. The gyro gets the last correction held while the temperature is stale, either
way. ``--gaps-s`` are the readings removed: a 600 s gap at 1 Hz is a 601 s interval. Only the
defaults and the guard are set, so the same script measures an older checkout
(``PYTHONPATH=<worktree>``, ``--restart-only``).
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

from fog_temp_comp.core.compensator_types import GuardSettings
from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS
from fog_temp_comp.core.evaluate import compensate_record, score_record
from fog_temp_comp.core.model_choice import choose_and_calibrate
from fog_temp_comp.tools.plants import draw_plant
from fog_temp_comp.tools.simulate import SimulatedRun, SimulationConfig, simulate_plan

RUNS = [('cycle', 0.2), ('cycle', 1.0), ('cycle', 0.5)]
PLACES = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)


def without_readings(run: SimulatedRun, place: float, gap_s: float) -> SimulatedRun:
    """``run`` without its temperature readings of ``gap_s`` s from ``place`` (0-1) into it."""
    t = run.temp_stamps_s
    start = t[0] + place * (t[-1] - t[0])
    keep = ~((t >= start) & (t < start + gap_s))
    return dataclasses.replace(
        run, temp_stamps_s=t[keep], temperature_degC=run.temperature_degC[keep]
    )


def range_and_stability(run: SimulatedRun, corrected_rad_s: np.ndarray) -> np.ndarray:
    """(2, 3): the 10 s range and the 100 s stability after, per axis, deg/h."""
    s10 = score_record('c', run.imu_stamps_s, run.rates_rad_s, corrected_rad_s, (10.0,))
    s100 = score_record('c', run.imu_stamps_s, run.rates_rad_s, corrected_rad_s, (100.0,))
    return np.array([[s.range_after_deg_h for s in s10], [s.stability_after_deg_h for s in s100]])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--plants', nargs='+', default=['default', '100', '105'])
    parser.add_argument(
        '--gaps-s', type=float, nargs='+', default=[15.0, 120.0, 600.0, 1200.0, 3600.0]
    )
    parser.add_argument(
        '--restart-only', action='store_true', help='only the restart (code before the bridge)'
    )
    parser.add_argument(
        '--bridge-s', type=float, help='temperature_bridge_s of the second guard (default: its)'
    )
    args = parser.parse_args()
    guards: dict[str, dict[str, float]] = {'restart': {'temperature_bridge_s': 0.0}, 'default': {}}
    if args.bridge_s is not None:
        guards = {
            'restart': guards['restart'],
            f'bridge {args.bridge_s:g} s': {'temperature_bridge_s': args.bridge_s},
        }
    if args.restart_only:
        guards = {'restart': {}}
    print(
        '| plant | run | gap s | guard | 10 s range / clean: median | max | '
        '100 s stability / clean: median | max |'
    )
    print('|---|---|---|---|---|---|---|---|')
    for plant in args.plants:
        started = time.perf_counter()
        cfg = SimulationConfig(imu_hz=2.0) if plant == 'default' else draw_plant(int(plant))
        runs = list(simulate_plan(cfg, seed=0, runs=RUNS).values())
        train, tests = runs[0], runs[1:]
        coeffs = choose_and_calibrate([train.as_record()], RECOMMENDED_SETTINGS)[0].coefficients
        for run in tests:
            clean = range_and_stability(run, compensate_record(run.as_record(), coeffs))
            for gap_s in args.gaps_s:
                for label, guard in guards.items():
                    ratios = np.array(
                        [
                            range_and_stability(
                                run,
                                compensate_record(
                                    without_readings(run, place, gap_s).as_record(),
                                    coeffs,
                                    guard=GuardSettings(**guard),  # type: ignore[arg-type]
                                ),
                            )
                            / clean
                            for place in PLACES
                        ]
                    )
                    r10, s100 = ratios[:, 0, :], ratios[:, 1, :]
                    print(
                        f'| {plant} | {run.name} | {gap_s:g} | {label} | '
                        f'{np.median(r10):.3f} | {r10.max():.3f} | '
                        f'{np.median(s100):.3f} | {s100.max():.3f} |',
                        flush=True,
                    )
        print(f'(plant {plant}: {time.perf_counter() - started:.0f} s)', flush=True)


if __name__ == '__main__':
    main()
