"""Side study (not the package): a causal "lag bank" of the online Tdot estimate.

Question: does a small bank of first-order lags of the default pipeline's causal Tdot estimate
(coefficients fitted by least squares beside the default's static terms, in place of its
``Tdot``/``Tdot_lag``) beat the default on the foreign plants without hurting the study's own?

Run by hand, one process (two stages; the first caches each plant's series in ``--cache``,
about 50 MB a plant-seed, 15 s each)::

    python benchmarks/lag_bank_study.py collect --which foreign --plants 0 1 ... --seeds 0
    python benchmarks/lag_bank_study.py collect --which study --plants 100 ... --seeds 0 1
    python benchmarks/lag_bank_study.py evaluate --keys foreign_0_0 ... --bank lags4 --per-plant

Design frozen before the held-back plants were scored: bank ``lags4`` (Tdot and its lags of
30, 100, 300 and 1000 s) in place of ``Tdot``/``Tdot_lag``, OLS, tolerance 2 %. Findings
(session notes, seed 0 unless said): the bank does not move the medians (foreign looked-at
100 s 1.72x -> 1.72x the oracle, study 1.43x -> 1.47x); the training run's block
cross-validation prefers it on most plants by under 2 % and its preference predicts the
held-out change poorly (Spearman 0.25 over 40 plant-seeds); with the 2 % margin it takes the
bank on a few plants, helping the ringing chamber (plant 23, 100 s -13 %, 10 s ratio 0.48 ->
0.39) and plant 27 on both seeds, but seed 1 adds three plants it makes worse. Ridge on the
bank's columns is worse (the lead needs large opposite coefficients).

``collect``: per plant, the default pipeline exactly as ``foreign_plants.py`` / ``accuracy.py``
run it (:func:`choose_and_calibrate` with no flags, :func:`compensate_record` on the held-out
runs), its figures and the oracle's (:func:`accuracy.metrics`); then the default's own causal
estimate (the temperature, Tdot and lagged Tdot its compensator uses at every gyro sample, after
its guards) is read out by replaying every run, the training run too, through a
:class:`Compensator` with the default's estimator settings and a model whose three "axes" are
the terms ``T``, ``Tdot`` and ``Tdot_lag`` with unit coefficients.

``evaluate``: variants from the cache, scored by :func:`accuracy.metrics` against the oracle:

- ``a``: the default as it is (its compensated outputs);
- ``a_refit``: the default's terms refitted by OLS on the read-out series (a check of the
  read-out: it should come close to ``a``);
- ``b``: the default's static terms (its terms less ``Tdot``, ``Tdot_lag``) plus the bank:
  the estimated Tdot and its causal first-order lags (``scipy.signal.lfilter``), or a
  Laguerre basis, fitted by OLS (optionally ridge on the bank's columns) on the training run's
  10 s bins;
- ``c``: ``b`` where a 5-block time cross-validation on the training run (fit on four blocks,
  score the fifth; geometric mean of the 10 s and 100 s stability ratios after/before over
  blocks and axes, as ``calibrate``'s score) prefers it to ``a_refit``'s terms by more than
  ``--tolerance``; ``a`` otherwise.
"""

from __future__ import annotations

import argparse
import itertools
import json
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from accuracy import TRAINING_RUN, metrics, pipeline_settings
from scipy import signal

from fog_temp_comp.core.compensator import Compensator, replay
from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS
from fog_temp_comp.core.evaluate import compensate_record
from fog_temp_comp.core.grid import bin_means
from fog_temp_comp.core.model import DriftModel, design_matrix
from fog_temp_comp.core.model_choice import choose_and_calibrate
from fog_temp_comp.core.units import DEG_H_PER_RAD_S, RAD_S_PER_DEG_H

FIGURES = ('r10', 's100', 'range_cycles', 'range_soaks')
READOUT_TERMS = ('T', 'Tdot', 'Tdot_lag')
BANKS = {
    # name: ('lags', time constants s, 0 = Tdot itself) or ('laguerre', pole time constant s, n)
    'lags4': ('lags', (0.0, 30.0, 100.0, 300.0, 1000.0)),
    'lags3': ('lags', (0.0, 60.0, 240.0, 960.0)),
    'lags2': ('lags', (0.0, 100.0, 400.0)),
    'lag_fine': ('lags', (0.0, 20.0, 60.0, 180.0, 540.0)),
    'laguerre150': ('laguerre', 150.0, 4),
    'laguerre300': ('laguerre', 300.0, 4),
}
BIN_S = 10.0
BLOCKS = 5


# ----------------------------------------------------------------------------- collect
def _plant_runs(which: str, plant: int, seed: int) -> tuple[dict[str, object], dict[str, str]]:
    if which == 'foreign':
        from foreign_plants import describe as f_describe
        from foreign_plants import draw_foreign_plant, simulate_foreign_plan

        p = draw_foreign_plant(plant)
        return simulate_foreign_plan(p, seed), {k: str(v) for k, v in f_describe(p).items()}
    from fog_temp_comp.tools.plants import describe, draw_plant
    from fog_temp_comp.tools.simulate import simulate_plan

    cfg = draw_plant(plant)
    return simulate_plan(cfg, seed=seed), {k: str(v) for k, v in describe(cfg).items()}


def readout(record: object, coeffs: object) -> np.ndarray:
    """(N, 3): T degC, Tdot and lagged Tdot degC/min the default's compensator uses per sample."""
    base = coeffs.model  # type: ignore[attr-defined]
    model = DriftModel(
        READOUT_TERMS, np.eye(3), base.temperature_range_degC, base.tdot_range_degC_per_min
    )
    comp = Compensator(model, coeffs.denoise)  # type: ignore[attr-defined]
    zeros = np.zeros_like(record.rates_rad_s)  # type: ignore[attr-defined]
    out = replay(
        comp,
        record.imu_stamps_s,  # type: ignore[attr-defined]
        zeros,
        record.temp_stamps_s,  # type: ignore[attr-defined]
        record.temperature_degC,  # type: ignore[attr-defined]
    )
    return -out * DEG_H_PER_RAD_S


def collect(which: str, plant: int, seed: int, cache: Path) -> None:
    t0 = time.perf_counter()
    runs, desc = _plant_runs(which, plant, seed)
    heldout = {n: r for n, r in runs.items() if n != TRAINING_RUN}
    train = [runs[TRAINING_RUN].as_record()]
    # as foreign_plants.py's / accuracy.py's default row: calibrate with no flags
    result, _, score = choose_and_calibrate(
        train, pipeline_settings(RECOMMENDED_SETTINGS.kalman_hysteresis_quanta)
    )
    coeffs = result.coefficients
    t_cal = time.perf_counter() - t0
    default = {n: compensate_record(r.as_record(), coeffs) for n, r in heldout.items()}
    oracle = {n: r.rates_rad_s - r.true_drift_deg_h * RAD_S_PER_DEG_H for n, r in heldout.items()}
    arrays: dict[str, np.ndarray] = {}
    for name, run in runs.items():
        arrays[f'{name}/stamps'] = run.imu_stamps_s
        arrays[f'{name}/raw'] = run.rates_rad_s
        arrays[f'{name}/est'] = readout(run.as_record(), coeffs)
        if name != TRAINING_RUN:
            arrays[f'{name}/default'] = default[name]
    key = f'{which}_{plant}_{seed}'
    np.savez(cache / f'{key}.npz', **arrays)
    meta = {
        'key': key,
        'which': which,
        'plant': plant,
        'seed': seed,
        'describe': desc,
        'chosen': score.structure.name,
        'terms': list(coeffs.model.terms),
        'coefficients': coeffs.model.coefficients.tolist(),
        'oracle': metrics(runs, oracle),
        'default': metrics(runs, default),
        'calibrate_s': t_cal,
        'total_s': time.perf_counter() - t0,
    }
    (cache / f'{key}.json').write_text(json.dumps(meta, indent=1))
    print(
        f'{key}: {meta["chosen"]}; calibrate {t_cal:.0f} s, total {meta["total_s"]:.0f} s',
        flush=True,
    )


# ----------------------------------------------------------------------------- bank
def bank_columns(
    tdot: np.ndarray, dt_s: float, bank: tuple, *, with_tdot: bool = True
) -> np.ndarray:
    """Causal regressors of the bank from the Tdot series (N,) sampled every ``dt_s``.

    ``with_tdot``: the estimate itself is a column (False where the static terms hold it).
    """
    u = np.nan_to_num(tdot)
    cols = []
    if bank[0] == 'lags':
        for tau in bank[1]:
            if tau <= 0:
                if with_tdot:
                    cols.append(u)
                continue
            a = np.exp(-dt_s / tau)
            # y[k] = a y[k-1] + (1 - a) u[k], started in steady state on u[0]
            y, _ = signal.lfilter([1.0 - a], [1.0, -a], u, zi=[a * u[0]])
            cols.append(y)
    else:
        _, tau, n = bank
        a = np.exp(-dt_s / tau)
        if with_tdot:
            cols.append(u)  # the estimate itself, so that a lead stays possible
        # discrete Laguerre functions: a scaled first-order lag, then all-pass sections
        y = signal.lfilter([np.sqrt(1 - a * a)], [1.0, -a], u)
        cols.append(y)
        for _ in range(n - 1):
            y = signal.lfilter([-a, 1.0], [1.0, -a], y)
            cols.append(y)
    return np.stack(cols, axis=1)


def design(
    est: np.ndarray, static: tuple[str, ...], bank: tuple | None, dt_s: float
) -> np.ndarray:
    """Regressors per gyro sample: ``static`` terms of the read-out, then the bank (if any)."""
    t, r, rl = est[:, 0], est[:, 1], est[:, 2]
    x = design_matrix(np.nan_to_num(t), np.nan_to_num(r), static, np.nan_to_num(rl))
    if bank is None:
        return x
    extra = bank_columns(r, dt_s, bank, with_tdot='Tdot' not in static)
    return np.concatenate([x, extra], axis=1)


def fit(x: np.ndarray, y: np.ndarray, ridge: float, n_static: int) -> np.ndarray:
    """OLS of y (K, 3) on x (K, p), solved on unit-norm columns.

    ``ridge`` is added to the diagonal of the scaled normal matrix for the columns after
    ``n_static`` (the bank's); each scaled column has unit norm.
    """
    norms = np.sqrt(np.sum(x * x, axis=0))
    norms[norms == 0] = 1.0
    xs = x / norms
    g = xs.T @ xs
    pen = np.zeros(x.shape[1])
    pen[n_static:] = ridge
    coef = np.linalg.solve(g + np.diag(pen), xs.T @ y)
    return coef / norms[:, None]


def cv_score(xb: np.ndarray, yb: np.ndarray, ridge: float, n_static: int) -> float:
    """Score of a design by 5 contiguous blocks of the 10 s bins, each held out in turn.

    Geometric mean over blocks and axes of the 10 s and 100 s stability after / before.
    """
    n = yb.shape[0]
    edges = np.linspace(0, n, BLOCKS + 1).round().astype(int)
    logs = []
    for lo, hi in itertools.pairwise(edges.tolist()):
        test = np.zeros(n, bool)
        test[lo:hi] = True
        coef = fit(xb[~test], yb[~test], ridge, n_static)
        before = yb[test]
        after = before - xb[test] @ coef
        for m in (1, 10):
            k = (before.shape[0] // m) * m
            b = before[:k].reshape(-1, m, 3).mean(axis=1)
            a = after[:k].reshape(-1, m, 3).mean(axis=1)
            if b.shape[0] > 2:
                logs += list(np.log(np.std(a, axis=0, ddof=1) / np.std(b, axis=0, ddof=1)))
    return float(np.exp(np.mean(logs)))


def evaluate_one(
    key: str, cache: Path, bank_name: str, ridge: float, tolerance: float, augment: bool = False
) -> dict[str, object]:
    """Variants a, a_refit, b, c on one cached plant-seed (see the module docstring).

    ``augment``: the bank's lags join the default's own terms instead of replacing its
    ``Tdot`` / ``Tdot_lag``.
    """
    meta = json.loads((cache / f'{key}.json').read_text())
    data = np.load(cache / f'{key}.npz')
    names = sorted({k.split('/')[0] for k in data.files})
    runs = {
        n: SimpleNamespace(imu_stamps_s=data[f'{n}/stamps'], rates_rad_s=data[f'{n}/raw'])
        for n in names
    }
    own = tuple(meta['terms'])
    static = own if augment else tuple(t for t in own if t not in ('Tdot', 'Tdot_lag'))
    bank = BANKS[bank_name]
    st = data[f'{TRAINING_RUN}/stamps']
    dt_s = float(np.median(np.diff(st)))
    est = data[f'{TRAINING_RUN}/est']
    ok = np.all(np.isfinite(est), axis=1)
    y_full = data[f'{TRAINING_RUN}/raw'] * DEG_H_PER_RAD_S

    def binned(x: np.ndarray) -> np.ndarray:
        _, _, xb = bin_means(st[ok], x[ok], BIN_S)
        return xb

    _, _, yb = bin_means(st[ok], y_full[ok], BIN_S)
    x_own = binned(design(est, own, None, dt_s))
    x_bank = binned(design(est, static, bank, dt_s))
    coef_own = fit(x_own, yb, 0.0, x_own.shape[1])
    coef_bank = fit(x_bank, yb, ridge, len(static))
    score_own = cv_score(x_own, yb, 0.0, x_own.shape[1])
    score_bank = cv_score(x_bank, yb, ridge, len(static))
    use_bank = score_bank < (1.0 - tolerance) * score_own
    corrected: dict[str, dict[str, np.ndarray]] = {'a': {}, 'a_refit': {}, 'b': {}}
    for n in names:
        if n == TRAINING_RUN:
            continue
        e = data[f'{n}/est']
        raw = data[f'{n}/raw']
        bad = ~np.all(np.isfinite(e), axis=1)
        for v, (terms, b, coef) in {
            'a_refit': (own, None, coef_own),
            'b': (static, bank, coef_bank),
        }.items():
            out = raw - (design(e, terms, b, dt_s) @ coef) * RAD_S_PER_DEG_H
            out[bad] = np.nan
            corrected[v][n] = out
        corrected['a'][n] = data[f'{n}/default']
    corrected['c'] = corrected['b'] if use_bank else corrected['a']
    rows = {'oracle': meta['oracle']}
    for v, c in corrected.items():
        rows[v] = metrics(runs, c)  # type: ignore[arg-type]
    return {
        'key': key,
        'plant': meta['plant'],
        'describe': meta['describe'],
        'chosen': meta['chosen'],
        'rows': rows,
        'cv_own': score_own,
        'cv_bank': score_bank,
        'use_bank': bool(use_bank),
        'bank_coef_x': coef_bank[len(static) :, 0].tolist(),
    }


def rel(row: dict[str, float], oracle: dict[str, float], k: str) -> float:
    return row[k] / oracle[k] if k == 's100' else row[k] - oracle[k]


def summarise(results: list[dict[str, object]], title: str) -> str:
    lines = [
        f'### {title} ({len(results)} plant-seeds)',
        '',
        '| variant | 10 s ratio - oracle | 100 s / oracle | cycles range - oracle '
        '| soaks range - oracle | 100 s better >5 % vs a | 100 s worse >5 % vs a |',
        '|---|---|---|---|---|---|---|',
    ]
    for v in ('a', 'a_refit', 'b', 'c'):
        med = {
            k: float(np.median([rel(r['rows'][v], r['rows']['oracle'], k) for r in results]))
            for k in FIGURES
        }
        q = [r['rows'][v]['s100'] / r['rows']['a']['s100'] for r in results]
        better = sum(x < 0.95 for x in q)
        worse = sum(x > 1.05 for x in q)
        lines.append(
            f'| {v} | {med["r10"]:+.4f} | {med["s100"]:.3f} | {med["range_cycles"]:+.3f} '
            f'| {med["range_soaks"]:+.3f} | {better} | {worse} |'
        )
    used = sum(bool(r['use_bank']) for r in results)
    lines.append(f'\n(c) took the bank on {used}/{len(results)}')
    return '\n'.join(lines)


def per_plant(results: list[dict[str, object]]) -> str:
    lines = [
        '| plant | sensor | default chose | cv a | cv b | c uses b | 100 s / oracle a / b / c '
        '| 10 s ratio a / b / oracle | soaks a / b |',
        '|---|---|---|---|---|---|---|---|---|',
    ]
    for r in results:
        rows = r['rows']
        o = rows['oracle']
        lines.append(
            f'| {r["key"]} | {r["describe"].get("sensor", "")} | {r["chosen"]} '
            f'| {r["cv_own"]:.4f} | {r["cv_bank"]:.4f} | {"yes" if r["use_bank"] else "no"} '
            f'| {rows["a"]["s100"] / o["s100"]:.3f} / {rows["b"]["s100"] / o["s100"]:.3f} '
            f'/ {rows["c"]["s100"] / o["s100"]:.3f} '
            f'| {rows["a"]["r10"]:.4f} / {rows["b"]["r10"]:.4f} / {o["r10"]:.4f} '
            f'| {rows["a"]["range_soaks"]:.3f} / {rows["b"]["range_soaks"]:.3f} |'
        )
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    sub = parser.add_subparsers(dest='cmd', required=True)
    c = sub.add_parser('collect')
    c.add_argument('--which', choices=('foreign', 'study'), required=True)
    c.add_argument('--plants', type=int, nargs='+', required=True)
    c.add_argument('--seeds', type=int, nargs='+', default=[0])
    c.add_argument('--cache', type=Path, default=Path('/tmp/lagbank_cache'))
    e = sub.add_parser('evaluate')
    e.add_argument('--keys', nargs='+', required=True)
    e.add_argument('--cache', type=Path, default=Path('/tmp/lagbank_cache'))
    e.add_argument('--bank', choices=sorted(BANKS), default='lags4')
    e.add_argument('--ridge', type=float, default=0.0)
    e.add_argument('--tolerance', type=float, default=0.02)
    e.add_argument('--title', default='plants')
    e.add_argument('--per-plant', action='store_true')
    e.add_argument('--augment', action='store_true', help='bank beside Tdot/Tdot_lag')
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    if args.cmd == 'collect':
        args.cache.mkdir(parents=True, exist_ok=True)
        for p in args.plants:
            for s in args.seeds:
                collect(args.which, p, s, args.cache)
    else:
        results = [
            evaluate_one(k, args.cache, args.bank, args.ridge, args.tolerance, args.augment)
            for k in args.keys
        ]
        if args.per_plant:
            print(per_plant(results) + '\n')
        how = 'beside Tdot/Tdot_lag' if args.augment else 'replacing Tdot/Tdot_lag'
        print(
            summarise(
                results,
                f'{args.title}, bank {args.bank} {how}, ridge {args.ridge}, '
                f'tolerance {args.tolerance}',
            )
        )
    print(f'\n({time.perf_counter() - t0:.0f} s)')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
