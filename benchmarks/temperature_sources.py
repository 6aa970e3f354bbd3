"""Whether ``calibrate``'s per-sensor choice keeps the temperature sensor that corrects better.

Run by hand (not in CI)::

    .venv/bin/python benchmarks/temperature_sources.py           # looked-at plants, ~8 min
    .venv/bin/python benchmarks/temperature_sources.py --plants 8 9 10 11 12 13 14 15
    .venv/bin/python benchmarks/temperature_sources.py --plants 3 5 --workers 1

Where the bags carry several temperature sensors, ``calibrate`` runs its default model choice
(:func:`fog_temp_comp.core.model_choice.choose_and_calibrate`) on each sensor's readings and
keeps the one whose chosen pipeline has the best cross-validated score
(:func:`fog_temp_comp.core.sensor_choice.choose_source`). That score is the choice's own
estimate, from the training cycle alone; this study judges it against the oracle on the
held-out runs.

The plants are ``foreign_plants.py``'s (its generator, its protocol, its figures), each built
with both sensors: the same drawn plant (thermal network, drift, gyro noise, chamber, sensor
lag, noise, quantum and rate), read once at the housing node (ahead of the coil) and once at the
hub node (behind it) through the same drawn sensor lag (:func:`with_sensor`). Both variants are
simulated with the same seed, so the gyro rates, the true drift and the reading stamps are
bit-identical (asserted) and only the temperature readings differ (their noise draws are the
same too). The drawn ``sensor`` only says which one ``foreign_plants.py`` uses.

Per sensor: ``calibrate`` with no flags (as ``foreign_plants.py``'s ``default`` row, the same
base settings and options) on the 0.2 degC/min cycle, then the node's compensator replays the
0.3-1.0 degC/min cycles and the -40/-20/10/30 degC soaks; the figures are ``accuracy.py``'s
(median 10 s ratio after/before, median 100 s stability deg/h, worst 10 s range ratio on
cycles and on soaks) and its acceptance lines against the oracle (raw minus true drift).

The outcomes go to ``choose_source`` in the command's order (frame_ids sorted: ``housing``,
``hub``); it keeps the first within its tolerance of the best score (the score of the pipeline
that runs: the quantized-likelihood filter's where the choice kept it).

Rows of the per-plant table: ``oracle``, then ``housing`` and ``hub`` (each sensor's CV score,
chosen model and figures; ``<-`` marks the sensor ``choose_source`` kept). The verdict table
says per plant the lowest CV score's sensor, which sensor the choice kept (the two differ only
by the tolerance), which the old rule keeps (one topic carrying
several frame_ids: the frame_id that sorts first, ``housing``), and which one is better by the
oracle figures: primarily the median 100 s stability, the 10 s ratio as secondary (``disagree``
where the 10 s ratio would pick the other one), with the chosen sensor's 100 s over the better
one's.

The summary, per plant set (looked at: 0-7 and 16-31; held back: 8-15, never tuned on), counts
how often the choice keeps the oracle-better sensor, and gives for each way of picking --
``chosen`` (``choose_source``), ``old rule`` (housing), ``hub always``, ``housing always``,
``best of two`` (by the oracle's 100 s, an upper bound) -- the median figures, their medians
against the oracle and the acceptance lines met.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import multiprocessing
import time
import traceback
from collections.abc import Sequence

import numpy as np
from accuracy import (
    LIMITS,
    TRAINING_RUN,
    add_pipeline_options,
    checks,
    figure_cells,
    line_counts,
    median_excess,
    metrics,
    pipeline_settings,
)
from foreign_plants import (
    EXTRA_LOOKED_AT_PLANTS,
    HELDBACK_PLANTS,
    HOUSING,
    HUB,
    LAYER0,
    LOOKED_AT_PLANTS,
    N_LAYERS,
    ForeignPlant,
    draw_foreign_plant,
    simulate_foreign_plan,
)

from fog_temp_comp.core.evaluate import compensate_record
from fog_temp_comp.core.model_choice import choose_and_calibrate
from fog_temp_comp.core.sensor_choice import SourceOutcome, TemperatureSource, choose_source
from fog_temp_comp.core.units import RAD_S_PER_DEG_H
from fog_temp_comp.tools.simulate import SimulatedRun

#: the two sensors, by the frame_id each has on the shared temperature topic, in the order
#: ``calibrate`` lists them (sorted), which ``choose_source``'s tolerance favours
SENSORS = ('housing', 'hub')
TOPIC = '/fog/temperature'
#: the old rule: of a topic carrying several frame_ids, the one that sorts first
OLD_RULE = SENSORS[0]
#: the ways of picking a sensor the summary compares
STRATEGIES = ('chosen', 'old rule', 'hub always', 'housing always', 'best of two')
DEFAULT_PLANTS = (*LOOKED_AT_PLANTS, *EXTRA_LOOKED_AT_PLANTS)
#: 100 s figures within this factor of each other count as a tie in the "clear" count
#: (the 100 s acceptance line's width)
CLEAR_FACTOR = LIMITS['s100']


def with_sensor(plant: ForeignPlant, sensor: str) -> ForeignPlant:
    """``plant`` with its temperature sensor (same lag states) fed by the ``sensor`` node."""
    if sensor == plant.sensor:
        return plant
    n0 = LAYER0 + N_LAYERS
    taus = plant.sensor_taus_s
    a = np.zeros((n0 + len(taus), n0 + len(taus)))
    a[:n0, :n0] = plant.a[:n0, :n0]
    source = HOUSING if sensor == 'housing' else HUB
    for j, tau in enumerate(taus):
        a[n0 + j, n0 + j] = -1.0 / tau
        a[n0 + j, source if j == 0 else n0 + j - 1] = 1.0 / tau
    delay = np.linalg.solve(a[:n0, :n0], -np.ones(n0))  # steady-ramp delays, s
    return dataclasses.replace(plant, a=a, sensor=sensor, sensor_node_delay_s=float(delay[source]))


def assert_same_gyro(first: dict[str, SimulatedRun], second: dict[str, SimulatedRun]) -> None:
    """The two variants' runs differ only in the temperature readings (bit for bit)."""
    assert first.keys() == second.keys()
    for name, a in first.items():
        b = second[name]
        for field in ('imu_stamps_s', 'rates_rad_s', 'true_drift_deg_h', 'temp_stamps_s'):
            assert np.array_equal(getattr(a, field), getattr(b, field)), (name, field)


def study_one(job: tuple[int, int, float, bool]) -> dict[str, object]:
    """The default calibration on each sensor of one plant, the choice, and the oracle figures.

    ``job``: (plant, seed, ``kalman_hysteresis_quanta``, Gaussian readings), as
    ``foreign_plants.py``.
    """
    plant_seed, seed, hysteresis_quanta, gaussian_readings = job
    t0 = time.perf_counter()
    drawn = draw_foreign_plant(plant_seed)
    plants = {s: with_sensor(drawn, s) for s in SENSORS}
    runs = {s: simulate_foreign_plan(plants[s], seed) for s in SENSORS}
    assert_same_gyro(runs[SENSORS[0]], runs[SENSORS[1]])
    common = runs[SENSORS[0]]
    heldout_names = [n for n in common if n != TRAINING_RUN]
    oracle = {
        n: common[n].rates_rad_s - common[n].true_drift_deg_h * RAD_S_PER_DEG_H
        for n in heldout_names
    }
    rows: dict[str, dict[str, float]] = {'oracle': metrics(common, oracle)}
    outcomes = []
    cal_s: dict[str, float] = {}
    for s in SENSORS:
        source = TemperatureSource(TOPIC, s)
        t_cal = time.perf_counter()
        try:
            # as foreign_plants.py's default row: calibrate with no flags
            result, _, chosen = choose_and_calibrate(
                [runs[s][TRAINING_RUN].as_record()],
                pipeline_settings(hysteresis_quanta),
                quantized_likelihood=not gaussian_readings,
            )
            outcomes.append(SourceOutcome(source, result, chosen=chosen))
            corrected = {
                n: compensate_record(runs[s][n].as_record(), result.coefficients)
                for n in heldout_names
            }
            rows[s] = metrics(runs[s], corrected)
        except Exception:
            outcomes.append(SourceOutcome(source, error=traceback.format_exc()))
            rows[s] = dict.fromkeys(LIMITS, math.nan)
        cal_s[s] = time.perf_counter() - t_cal
    try:
        picked = choose_source(outcomes).source.frame_id
    except ValueError:
        picked = ''
    return {
        'plant': plant_seed,
        'seed': seed,
        'drawn_sensor': drawn.sensor,
        'sensor_lag_s': f'{sum(drawn.sensor_taus_s):.0f} ({len(drawn.sensor_taus_s)})',
        'coil_lag_s': drawn.coil_delay_s,
        'vs_coil_s': {s: plants[s].sensor_delay_s for s in SENSORS},
        'quantum_degC': drawn.quantum_degC,
        'temp_hz': drawn.temp_hz,
        'rows': rows,
        'criterion': {o.source.frame_id: o.criterion for o in outcomes},
        'model': {
            o.source.frame_id: o.chosen.structure.name if o.chosen is not None else 'CRASHED'
            for o in outcomes
        },
        'errors': {o.source.frame_id: o.error for o in outcomes if o.error},
        'picked': picked,
        'calibrate_s': cal_s,
        'total_s': time.perf_counter() - t0,
    }


def better_by(rows: dict[str, dict[str, float]], key: str) -> str:
    """The sensor with the lower ``key`` figure (a crashed one never; the first of equal ones)."""
    ok = [s for s in SENSORS if math.isfinite(rows[s][key])]
    return min(ok, key=lambda s: rows[s][key]) if ok else ''


def oracle_best(rows: dict[str, dict[str, float]]) -> str:
    """Better by the median 100 s stability; the 10 s ratio breaks an exact tie."""
    ok = [s for s in SENSORS if math.isfinite(rows[s]['s100'])]
    return min(ok, key=lambda s: (rows[s]['s100'], rows[s]['r10'])) if ok else ''


def with_strategies(res: dict[str, object]) -> dict[str, dict[str, float]]:
    """The plant's rows plus one per way of picking a sensor (a failed pick: NaN figures)."""
    rows = res['rows']
    assert isinstance(rows, dict)
    nan_row = dict.fromkeys(LIMITS, math.nan)
    picks = {
        'chosen': str(res['picked']),
        'old rule': OLD_RULE,
        'hub always': 'hub',
        'housing always': 'housing',
        'best of two': oracle_best(rows),
    }
    return {**rows, **{k: rows[s] if s else nan_row for k, s in picks.items()}}


def format_plants(results: Sequence[dict[str, object]]) -> str:
    """Markdown: per plant, the oracle and each sensor's score, model and figures."""
    lines = [
        '| plant | drawn sensor | coil lag s | sensor lag s (order) | quantum degC | temp Hz '
        '| row | sensor - coil s | CV score | model chosen | 10 s ratio | 100 s deg/h '
        '| range cycles | range soaks | meets (vs oracle) |',
        '|---' * 15 + '|',
    ]
    for res in results:
        rows = res['rows']
        vs_coil = res['vs_coil_s']
        crit = res['criterion']
        model = res['model']
        assert isinstance(rows, dict)
        assert isinstance(vs_coil, dict)
        assert isinstance(crit, dict)
        assert isinstance(model, dict)
        head = (
            f'| {res["plant"]} | {res["drawn_sensor"]} | {res["coil_lag_s"]:.0f} '
            f'| {res["sensor_lag_s"]} | {res["quantum_degC"]:.4g} | {res["temp_hz"]:.2f} '
        )
        lines.append(f'{head}| oracle | | | | {figure_cells(rows["oracle"])} | |')
        for s in SENSORS:
            ok = checks({'default': rows[s], 'oracle': rows['oracle']})
            meets = ' '.join(k for k, v in ok.items() if v) or '-'
            mark = ' <-' if s == res['picked'] else ''
            lines.append(
                f'| | | | | | | {s}{mark} | {vs_coil[s]:+.0f} | {crit[s]:.4f} | {model[s]} '
                f'| {figure_cells(rows[s])} | {meets} |'
            )
    return '\n'.join(lines)


def format_verdicts(results: Sequence[dict[str, object]]) -> str:
    """Markdown: per plant, the choice, the old rule and the oracle's better sensor."""
    lines = [
        '| plant | CV hub / housing | lowest CV | chosen | old rule | better by 100 s '
        '| better by 10 s '
        '| 100 s hub / housing | chosen right? | chosen 100 s / best |',
        '|---' * 10 + '|',
    ]
    for res in results:
        rows = res['rows']
        crit = res['criterion']
        assert isinstance(crit, dict)
        lowest = min(SENSORS, key=lambda s: crit[s])
        assert isinstance(rows, dict)
        best, by10 = oracle_best(rows), better_by(rows, 'r10')
        picked = str(res['picked'])
        loss = rows[picked]['s100'] / rows[best]['s100'] if picked and best else math.nan
        ratio = rows['hub']['s100'] / rows['housing']['s100']
        lines.append(
            f'| {res["plant"]} | {crit["hub"]:.4f} / {crit["housing"]:.4f} | {lowest} '
            f'| {picked or "-"} '
            f'| {OLD_RULE} | {best or "-"} | {by10 or "-"}{" (disagree)" if by10 != best else ""} '
            f'| {ratio:.3f} | {"yes" if picked == best else "NO"} | {loss:.3f} |'
        )
    return '\n'.join(lines)


def agreement(results: Sequence[dict[str, object]]) -> str:
    """How often the choice and the old rule keep the oracle-better sensor."""
    n = len(results)
    chosen = old = chosen10 = clear = chosen_clear = old_clear = disagree = 0
    for res in results:
        rows = res['rows']
        assert isinstance(rows, dict)
        best = oracle_best(rows)
        by10 = better_by(rows, 'r10')
        picked = res['picked']
        chosen += int(picked == best)
        old += int(best == OLD_RULE)
        chosen10 += int(picked == by10)
        disagree += int(by10 != best)
        a, b = rows['hub']['s100'], rows['housing']['s100']
        if max(a, b) > CLEAR_FACTOR * min(a, b):
            clear += 1
            chosen_clear += int(picked == best)
            old_clear += int(best == OLD_RULE)
    return (
        f'choice keeps the oracle-better sensor (100 s): {chosen}/{n}; by the 10 s ratio: '
        f'{chosen10}/{n}; old rule ({OLD_RULE}): {old}/{n}; the 100 s and 10 s figures '
        f'disagree on {disagree}/{n}.\n'
        f'plants where the sensors differ by more than {CLEAR_FACTOR:.2f}x on 100 s: {clear}/{n}; '
        f'of these the choice keeps the better one on {chosen_clear}/{clear}, '
        f'the old rule on {old_clear}/{clear}.'
    )


def summary(results: Sequence[dict[str, object]]) -> str:
    """Per way of picking: median figures, medians against the oracle, lines met."""
    picked = [{'rows': with_strategies(r)} for r in results]
    n = len(results)
    lines = [
        '| picking | plants | 10 s ratio | 100 s deg/h | range cycles | range soaks '
        '| meets 10 s | 100 s | cycles | soaks | all four '
        '| medians vs oracle (10 s - o / 100 s / o / cycles - o / soaks - o) |',
        '|---' * 12 + '|',
    ]
    for name in ('oracle', *STRATEGIES):
        med = {
            k: float(np.median([r['rows'][name][k] for r in picked]))  # type: ignore[index]
            for k in LIMITS
        }
        if name == 'oracle':
            lines.append(f'| oracle | {n} | {figure_cells(med)} | | | | | | |')
            continue
        counts, every = line_counts(picked, name)
        exc = median_excess(picked, name)
        lines.append(
            f'| {name} | {n} | {figure_cells(med)} | {counts["r10"]}/{n} | {counts["s100"]}/{n} '
            f'| {counts["range_cycles"]}/{n} | {counts["range_soaks"]}/{n} | {every}/{n} '
            f'| {exc["r10"]:+.4f} / {exc["s100"]:.3f}x / {exc["range_cycles"]:+.3f} '
            f'/ {exc["range_soaks"]:+.3f} |'
        )
    return '\n'.join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the study; print the tables."""
    parser = argparse.ArgumentParser(description=(__doc__ or '').split('\n')[0])
    parser.add_argument('--plants', type=int, nargs='+', default=list(DEFAULT_PLANTS))
    parser.add_argument('--seeds', type=int, nargs='+', default=[0])
    parser.add_argument('--workers', type=int, default=2)
    add_pipeline_options(parser)
    args = parser.parse_args(argv)
    jobs = [
        (p, s, args.hysteresis_quanta, args.gaussian_readings)
        for p in args.plants
        for s in args.seeds
    ]
    t0 = time.perf_counter()
    results = []
    with multiprocessing.get_context('spawn').Pool(args.workers) as pool:
        for res in pool.imap(study_one, jobs):
            cal = res['calibrate_s']
            crit = res['criterion']
            print(
                f'  plant {res["plant"]} seed {res["seed"]}: CV hub {crit["hub"]:.4f} '
                f'housing {crit["housing"]:.4f}, picked {res["picked"] or "-"}, calibrate '
                f'{cal["hub"]:.0f} + {cal["housing"]:.0f} s, total {res["total_s"]:.0f} s',
                flush=True,
            )
            for s, err in res['errors'].items():
                print(f'  plant {res["plant"]} seed {res["seed"]} sensor {s} CRASHED:\n{err}')
            results.append(res)
    print('\nPer plant (both sensors on the same plant and gyro):\n\n' + format_plants(results))
    print('\nVerdicts:\n\n' + format_verdicts(results))
    sets = (
        ('looked at', (*LOOKED_AT_PLANTS, *EXTRA_LOOKED_AT_PLANTS)),
        ('held back', HELDBACK_PLANTS),
    )
    seen: set[int] = set()
    for name, plants in sets:
        subset = [r for r in results if r['plant'] in plants]
        seen.update(plants)
        if subset:
            print(f'\n## {name} ({len(subset)} plant-seeds)\n\n{agreement(subset)}\n')
            print(summary(subset))
    other = [r for r in results if r['plant'] not in seen]
    if other:
        print(f'\n## other plants ({len(other)} plant-seeds)\n\n{agreement(other)}\n')
        print(summary(other))
    print(f'\n(total {time.perf_counter() - t0:.0f} s, {args.workers} workers)')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
