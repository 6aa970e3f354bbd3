"""Accuracy against chamber time, with and without the fleet prior, on a simulated fleet.

A fleet of ``--units`` gyros of one model (drawn by :func:`fog_temp_comp.tools.fleet_sim.draw_unit`
around the realistic chamber of :data:`~fog_temp_comp.tools.simulate.REALISTIC`: +-1 deg/h D0,
+-1e-3 deg/h/degC DT, 8 % DTdot, 20 % T^2, 15 % coil lag from unit to unit) is calibrated on the
full 0.2 degC/min cycle (19.7 h; T^2 terms, fitted coil lag); :func:`estimate_prior` gives
the prior. Then ``--new`` other units of the model are each calibrated on a short run of two
designs:

- ``first``: the first 2 to 18 h of their own 0.2 degC/min cycle (a full cycle stopped early:
  the first 8 h see only 20..60 degC and ramps of one sign);
- ``cycle``: the full -40..60 degC cycle compressed into 1 to 8 h
  (:func:`~fog_temp_comp.tools.fleet_sim.short_cycle`: soaks of 1/8 of the time, the fastest
  ramps that fit, 5.3 degC/min at 1 h, 0.67 degC/min at 8 h);

each alone (``calibrate --fit-coil-lag``: least squares, the unit's own coil lag, no fleet
knowledge) and with the prior (``calibrate --prior``), and on the full 0.2 degC/min cycle
alone (the reference). Every calibration is judged on the unit's own held-out runs (1, 0.5 and
0.2 degC/min cycles, full length, other noise): the 100 s bias stability after compensation
(std of 100 s means, deg/h, mean over axes and runs), as ``evaluate`` prints it.

    .venv/bin/python benchmarks/fleet_prior.py [--units 50] [--new 8] [--seed 0] \
        [--designs first cycle]
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

from fog_temp_comp.core.calibration import CalibrationError, calibrate_detailed
from fog_temp_comp.core.coefficients import Coefficients
from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS
from fog_temp_comp.core.evaluate import compensate_record, score_record
from fog_temp_comp.core.prior import calibrate_with_prior, estimate_prior
from fog_temp_comp.core.record import ChamberRecord
from fog_temp_comp.tools.fleet_sim import cut_run, draw_unit, short_cycle
from fog_temp_comp.tools.simulate import REALISTIC, SimulatedRun, SimulationConfig, simulate_run

TERMS = ('const', 'T', 'Tdot', 'T2')
#: chamber hours of each short-run design
HOURS = {'first': (2, 4, 8, 14, 18), 'cycle': (1, 1.5, 2, 4, 8)}
DESIGN_NAMES = {
    'first': 'first hours of the 0.2 degC/min cycle',
    'cycle': 'full-range cycle in that time',
}
HELDOUT = (1.0, 0.5, 0.2)  # cycle rates (degC/min) of the held-out runs
FITS = ('alone', 'prior')


def stability_100s(coeffs: Coefficients, runs: list[ChamberRecord]) -> float:
    """Mean over axes and runs of the 100 s bias stability after compensation, deg/h."""
    values = []
    for record in runs:
        corrected = compensate_record(record, coeffs)
        scores = score_record('', record.imu_stamps_s, record.rates_rad_s, corrected, (100.0,))
        values += [s.stability_after_deg_h for s in scores]
    return float(np.mean(values))


def short_run(design: str, hours: float, unit: SimulationConfig, full: SimulatedRun, seed: int):
    """The short calibration run of ``design`` lasting ``hours``."""
    if design == 'first':
        return cut_run(full, hours * 3600.0).as_record()
    cfg, rate = short_cycle(unit, hours)
    return simulate_run('cycle', rate, cfg, seed=seed).as_record()


def print_table(designs, absolute, ratios, refused) -> None:
    """One row per design and chamber time: median (worst) excess of each fit."""
    print(
        '| design | chamber time | '
        + ' | '.join(f'{f}: median deg/h, excess (worst)' for f in FITS)
        + ' |'
    )
    print('|---|---|' + '---|' * len(FITS))
    for design in designs:
        for hours in HOURS[design]:
            cells = []
            for name in FITS:
                key = (design, hours, name)
                r, n_refused = ratios.get(key, []), refused.get(key, 0)
                note = f' ({n_refused} refused)' if n_refused else ''
                if not r:
                    cells.append(f'-{note}')
                    continue
                cells.append(
                    f'{np.median(absolute[key]):.4f}, {100 * np.median(r):+.1f} % '
                    f'({100 * np.max(r):+.0f} %){note}'
                )
            print(f'| {design} | {hours:g} h | ' + ' | '.join(cells) + ' |')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--units', type=int, default=50, help='fleet units behind the prior')
    parser.add_argument('--new', type=int, default=8, help='new units judged')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--designs', nargs='+', choices=sorted(HOURS), default=list(HOURS))
    args = parser.parse_args()
    start = time.perf_counter()
    base = dataclasses.replace(REALISTIC, imu_hz=1.0, temp_hz=1.0)
    settings = RECOMMENDED_SETTINGS
    rng = np.random.default_rng((args.seed, 1414))
    fleet = []
    for k in range(args.units):
        unit = draw_unit(base, rng)
        run = simulate_run('cycle', 0.2, unit, seed=args.seed * 10_000 + k).as_record()
        result = calibrate_detailed([run], settings, terms=TERMS, fit_coil_lag=True)
        fleet.append((f'u{k}', result.coefficients))
    prior, notes = estimate_prior(fleet)
    print(
        f'prior from {len(prior.units)} of {args.units} units ({len(notes)} left out), '
        f'coil lag {prior.settings.coil_lag_s:.0f} s; {time.perf_counter() - start:.0f} s'
    )
    ratios: dict[tuple[str, float, str], list[float]] = {}
    refused: dict[tuple[str, float, str], int] = {}
    absolute: dict[tuple[str, float, str], list[float]] = {}
    references = []
    for k in range(args.new):
        unit = draw_unit(base, rng)
        seed = args.seed * 10_000 + 5000 + 10 * k
        full = simulate_run('cycle', 0.2, unit, seed=seed)
        heldout = [
            simulate_run('cycle', rate, unit, seed=seed + 1 + j).as_record()
            for j, rate in enumerate(HELDOUT)
        ]
        reference = calibrate_detailed(
            [full.as_record()], settings, terms=TERMS, fit_coil_lag=True
        ).coefficients
        ref = stability_100s(reference, heldout)
        references.append(ref)
        for design in args.designs:
            for hours in HOURS[design]:
                short = short_run(design, hours, unit, full, seed + 7)
                cases = {
                    'alone': lambda r=short: (
                        calibrate_detailed(
                            [r], settings, terms=TERMS, fit_coil_lag=True
                        ).coefficients
                    ),
                    'prior': lambda r=short: calibrate_with_prior([r], prior).coefficients,
                }
                for name, fit in cases.items():
                    key = (design, hours, name)
                    try:
                        value = stability_100s(fit(), heldout)
                    except CalibrationError:
                        refused[key] = refused.get(key, 0) + 1
                        continue
                    ratios.setdefault(key, []).append(value / ref - 1)
                    absolute.setdefault(key, []).append(value)
        print(f'unit {k + 1}/{args.new} done, {time.perf_counter() - start:.0f} s', flush=True)
    print(
        f'\n{args.new} new units; 100 s stability after compensation on their held-out runs '
        f'(cycles at {", ".join(f"{r:g}" for r in HELDOUT)} degC/min), against their own '
        f'full-run calibration (median {np.median(references):.4f} deg/h); designs: '
        + '; '.join(f'{d}: {DESIGN_NAMES[d]}' for d in args.designs)
        + '\n'
    )
    print_table(args.designs, absolute, ratios, refused)
    print(f'\ntotal {time.perf_counter() - start:.0f} s')


if __name__ == '__main__':
    main()
