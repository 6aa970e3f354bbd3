"""How much of the soaks' range error is the Tdot term: default vs its Tdot terms zeroed on soaks.

Run by hand (not in CI)::

    .venv/bin/python benchmarks/soak_tdot_share.py [--plants 100 101 ...] [--seeds 0 1]

For each plant and seed, the default ``calibrate`` on the 0.2 degC/min cycle, then the worst 10 s
range ratio (after / before) over the four soaks for: the oracle (raw rate minus the true
drift), the default pipeline, and the same coefficients with every Tdot term (``Tdot``,
``T_Tdot``, ``Tdot_lag``) set to 0, on the soaks only. Where the zeroed row meets the soak line
(oracle + 0.03) and the default does not, the soak's excess is the Tdot estimate's error.
"""

from __future__ import annotations

import argparse
import dataclasses
import multiprocessing
from collections.abc import Sequence

import numpy as np

from fog_temp_comp.core.coefficients import Coefficients
from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS
from fog_temp_comp.core.evaluate import compensate_record, score_record
from fog_temp_comp.core.model_choice import choose_and_calibrate
from fog_temp_comp.core.units import RAD_S_PER_DEG_H
from fog_temp_comp.tools.plants import TUNING_PLANTS, draw_plant
from fog_temp_comp.tools.simulate import SimulatedRun, simulate_plan


def worst_range(runs: dict[str, SimulatedRun], corrected: dict[str, np.ndarray]) -> float:
    """Worst 10 s range ratio after / before over the runs."""
    ratios = []
    for name, out in corrected.items():
        run = runs[name]
        for s in score_record(name, run.imu_stamps_s, run.rates_rad_s, out, (10.0,)):
            ratios.append(s.range_after_deg_h / s.range_before_deg_h)
    return float(max(ratios))


def without_tdot(coeffs: Coefficients) -> Coefficients:
    """``coeffs`` with every Tdot term's coefficient 0."""
    model = coeffs.model
    values = model.coefficients.copy()
    for i, term in enumerate(model.terms):
        if 'Tdot' in term:
            values[i] = 0.0
    return dataclasses.replace(coeffs, model=dataclasses.replace(model, coefficients=values))


def one(job: tuple[int, int]) -> tuple[int, int, str, dict[str, float]]:
    """The three soak rows of one plant and seed."""
    plant, seed = job
    runs = simulate_plan(draw_plant(plant), seed=seed)
    soaks = {n: r for n, r in runs.items() if n.startswith('soak')}
    result, _, chosen = choose_and_calibrate([runs['cycle_0p2'].as_record()], RECOMMENDED_SETTINGS)
    zeroed = without_tdot(result.coefficients)
    rows = {
        'oracle': worst_range(
            runs,
            {n: r.rates_rad_s - r.true_drift_deg_h * RAD_S_PER_DEG_H for n, r in soaks.items()},
        ),
        'default': worst_range(
            runs,
            {n: compensate_record(r.as_record(), result.coefficients) for n, r in soaks.items()},
        ),
        'Tdot zeroed': worst_range(
            runs, {n: compensate_record(r.as_record(), zeroed) for n, r in soaks.items()}
        ),
    }
    return plant, seed, chosen.structure.model, rows


def main(argv: Sequence[str] | None = None) -> int:
    """Print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--plants', type=int, nargs='+', default=list(TUNING_PLANTS))
    parser.add_argument('--seeds', type=int, nargs='+', default=[0, 1])
    args = parser.parse_args(argv)
    print('| plant | seed | chosen | oracle | default | Tdot zeroed on soaks |')
    print('|---|---|---|---|---|---|')
    jobs = [(p, s) for p in args.plants for s in args.seeds]
    with multiprocessing.Pool(2) as pool:
        for plant, seed, model, rows in pool.imap(one, jobs):
            print(
                f'| {plant} | {seed} | {model} | {rows["oracle"]:.3f} | {rows["default"]:.3f} | '
                f'{rows["Tdot zeroed"]:.3f} |',
                flush=True,
            )
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
