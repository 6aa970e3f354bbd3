"""Accuracy against chamber time, with and without the fleet prior, on a simulated fleet.

A fleet of ``--units`` gyros of one model (drawn by :func:`fog_temp_comp.tools.fleet_sim.draw_unit`
around the realistic chamber of :data:`~fog_temp_comp.tools.simulate.REALISTIC`: +-1 deg/h D0,
+-1e-3 deg/h/degC DT, 8 % DTdot, 20 % T^2, 15 % coil lag from unit to unit) is calibrated on the
full 0.2 degC/min cycle (19.7 h; T^2 terms, fitted coil lag); :func:`estimate_prior` gives
the prior.
Then ``--new`` other units of the model are each calibrated on the first 2 to 18 h of
their own cycle, alone (least squares, the fleet's Tdot settings), with the prior (the unit's own
coil lag searched near the fleet's) and with the prior and the fleet's lag, and on the
full cycle alone (the reference). Every calibration is judged on the unit's own held-out runs
(a 1 degC/min and a 0.5 degC/min cycle, full length): the 100 s bias stability after
compensation (std of 100 s means, deg/h, mean over axes and runs), as ``evaluate`` prints it.

    .venv/bin/python benchmarks/fleet_prior.py [--units 50] [--new 10] [--seed 0]
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
from fog_temp_comp.tools.fleet_sim import cut_run, draw_unit
from fog_temp_comp.tools.simulate import REALISTIC, simulate_run

TERMS = ('const', 'T', 'Tdot', 'T2')
HOURS = (2, 4, 8, 12, 14, 16, 18)
HELDOUT = (1.0, 0.5)  # cycle rates (degC/min) of the held-out runs


def stability_100s(coeffs: Coefficients, runs: list[ChamberRecord]) -> float:
    """Mean over axes and runs of the 100 s bias stability after compensation, deg/h."""
    values = []
    for record in runs:
        corrected = compensate_record(record, coeffs)
        scores = score_record('', record.imu_stamps_s, record.rates_rad_s, corrected, (100.0,))
        values += [s.stability_after_deg_h for s in scores]
    return float(np.mean(values))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--units', type=int, default=50, help='fleet units behind the prior')
    parser.add_argument('--new', type=int, default=10, help='new units judged')
    parser.add_argument('--seed', type=int, default=0)
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
    ratios: dict[tuple[str, int], list[float]] = {}
    refused: dict[tuple[str, int], int] = {}
    absolute: dict[tuple[str, int], list[float]] = {}
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
        absolute.setdefault(('full run alone', 0), []).append(ref)
        for hours in HOURS:
            short = cut_run(full, hours * 3600.0).as_record()
            cases = {
                'alone': lambda r=short: (
                    calibrate_detailed([r], prior.settings, terms=TERMS).coefficients
                ),
                'prior': lambda r=short: calibrate_with_prior([r], prior).coefficients,
                'prior, fleet lag': lambda r=short: (
                    calibrate_with_prior([r], prior, fit_coil_lag=False).coefficients
                ),
            }
            for name, fit in cases.items():
                try:
                    value = stability_100s(fit(), heldout)
                except CalibrationError:
                    refused[name, hours] = refused.get((name, hours), 0) + 1
                    continue
                ratios.setdefault((name, hours), []).append(value / ref - 1)
                absolute.setdefault((name, hours), []).append(value)
        print(f'unit {k + 1}/{args.new} done, {time.perf_counter() - start:.0f} s', flush=True)
    print(
        f'\n{args.new} new units; 100 s stability after compensation on their held-out runs '
        f'(cycles at {", ".join(f"{r:g}" for r in HELDOUT)} degC/min), against their own '
        f'full-run calibration (median {np.median(absolute["full run alone", 0]):.4f} deg/h)\n'
    )
    print('| chamber time | fit | units fitted | median deg/h | median excess | worst excess |')
    print('|---|---|---|---|---|---|')
    for hours in HOURS:
        for name in ('alone', 'prior', 'prior, fleet lag'):
            r = ratios.get((name, hours), [])
            n_refused = refused.get((name, hours), 0)
            if not r:
                print(f'| {hours} h | {name} | 0 ({n_refused} refused) | - | - | - |')
                continue
            print(
                f'| {hours} h | {name} | {len(r)}'
                + (f' ({n_refused} refused)' if n_refused else '')
                + f' | {np.median(absolute[name, hours]):.4f} | {100 * np.median(r):+.1f} % '
                f'| {100 * np.max(r):+.1f} % |'
            )
    print(f'\ntotal {time.perf_counter() - start:.0f} s')


if __name__ == '__main__':
    main()
