"""Cost of the compensator core per gyro message: ``Compensator.correct`` and ``replay``.

A 100 Hz gyro stream with a 1 Hz temperature interleaved (temperature first on equal stamps, as
in a replay) goes through a :class:`fog_temp_comp.core.compensator.Compensator` built from
``config/example_coefficients.yaml``, once per Tdot denoising method:

- ``loop us/msg``: a Python loop calling ``add_temperature`` and ``correct`` per message, as the
  node's callbacks do (rates passed as a tuple, like ``(w.x, w.y, w.z)``); total time over the
  number of gyro messages, so the temperature work is included;
- ``correct p50/p99/max``: each ``correct`` call timed on its own (perf_counter_ns; the ~0.1 us
  timer overhead is included);
- ``add_temperature mean/max``: each temperature call (the wavelet denoises a 512-sample window
  when a 10 s bin completes, i.e. every 10th call);
- ``replay us/msg``: :func:`fog_temp_comp.core.compensator.replay` on the whole arrays.

Before timing, 90 min of temperature (1 Hz) fill the estimator's window, so the numbers are
the steady state. Each number is the best of ``--repeat`` rounds (the percentiles: of the
round with the lowest p50); a round runs every method once. ``floor`` is the same loop with
``correct`` replaced by the least work a correction needs (``np.array(rate) - correction``)
and the ``none`` method's ``add_temperature``. Goal: <= 20 us per message one at a time.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np
from benchutil import machine, table

from fog_temp_comp.core.coefficients import load
from fog_temp_comp.core.compensator import Compensator, replay
from fog_temp_comp.core.rest import RestSettings

ROOT = Path(__file__).resolve().parents[1]
COEFFICIENTS = ROOT / 'config' / 'example_coefficients.yaml'
GOAL_US = 20.0
START_S = 1_700_000_000.0
WARMUP_S = 5400.0


def streams(duration_s: float, seed: int = 0) -> dict[str, np.ndarray]:
    """Gyro at 100 Hz and temperature at 1 Hz after the warm-up: a 0.5 degC/min ramp."""
    rng = np.random.default_rng(seed)
    t0 = START_S + WARMUP_S
    imu_t = t0 + np.arange(int(duration_s * 100)) / 100.0
    temp_t = START_S + np.arange(int(WARMUP_S + duration_s))
    temps = 0.0 + 0.5 * (temp_t - START_S) / 60.0 + rng.normal(0.0, 0.02, temp_t.size)
    temps = np.round(temps * 16.0) / 16.0
    rates = rng.normal(0.0, 1e-6, size=(imu_t.size, 3)) - 6e-5
    return {'imu_t': imu_t, 'rates': rates, 'temp_t': temp_t, 'temps': temps}


#: ``--rest-learning``: the bias learner at rest on (the benchmark's gyro is still: it learns)
REST = RestSettings(enabled=False)


def make(method: str) -> Compensator:
    coeffs = load(COEFFICIENTS)
    return Compensator(coeffs.model, dataclasses.replace(coeffs.denoise, method=method), rest=REST)


def events(s: dict[str, np.ndarray]) -> list[tuple[bool, int]]:
    """(is_imu, index) in stamp order, temperature first on ties."""
    n_imu = s['imu_t'].size
    order = np.lexsort(
        (np.r_[np.ones(n_imu), np.zeros(s['temp_t'].size)], np.r_[s['imu_t'], s['temp_t']])
    )
    return [(k < n_imu, k if k < n_imu else k - n_imu) for k in order.tolist()]


def warm_up(comp: Compensator, s: dict[str, np.ndarray]) -> int:
    """Feed the warm-up temperatures; return how many."""
    n = int(np.searchsorted(s['temp_t'], s['imu_t'][0]))
    for t, x in zip(s['temp_t'][:n].tolist(), s['temps'][:n].tolist(), strict=True):
        comp.add_temperature(t, x)
    return n


def run_loop(method: str, s: dict[str, np.ndarray], timed: bool) -> dict[str, float]:
    comp = make('none' if method == 'floor' else method)
    n_warm = warm_up(comp, s)
    imu_t = s['imu_t'].tolist()
    rates = [tuple(r) for r in s['rates'].tolist()]
    temp_t = s['temp_t'].tolist()
    temps = s['temps'].tolist()
    todo = [(imu, k) for imu, k in events(s) if imu or k >= n_warm]
    clock = time.perf_counter_ns
    correct, add = comp.correct, comp.add_temperature
    if method == 'floor':
        offset = np.zeros(3)

        def correct(stamp_s: float, rate: tuple[float, float, float]) -> np.ndarray:
            return np.array(rate, dtype=np.float64) - offset

    if not timed:
        start = clock()
        for imu, k in todo:
            if imu:
                correct(imu_t[k], rates[k])
            else:
                add(temp_t[k], temps[k])
        total = clock() - start
        return {'loop': total / 1e3 / len(imu_t)}
    imu_ns = np.empty(len(imu_t), dtype=np.int64)
    temp_ns = []
    for imu, k in todo:
        if imu:
            start = clock()
            correct(imu_t[k], rates[k])
            imu_ns[k] = clock() - start
        else:
            start = clock()
            add(temp_t[k], temps[k])
            temp_ns.append(clock() - start)
    if method != 'floor':
        assert comp.status.counters.imu_corrected == len(imu_t), comp.status.counters
    p50, p99 = np.percentile(imu_ns, [50, 99]) / 1e3
    temp_us = np.asarray(temp_ns) / 1e3
    return {
        'p50': p50,
        'p99': p99,
        'max': imu_ns.max() / 1e3,
        'temp_mean': temp_us.mean(),
        'temp_max': temp_us.max(),
    }


def run_replay(method: str, s: dict[str, np.ndarray]) -> float:
    comp = make(method)
    warm_up(comp, s)
    n_warm = int(np.searchsorted(s['temp_t'], s['imu_t'][0]))
    start = time.perf_counter()
    replay(comp, s['imu_t'], s['rates'], s['temp_t'][n_warm:], s['temps'][n_warm:])
    return (time.perf_counter() - start) * 1e6 / s['imu_t'].size


def _nan_last(value: float) -> float:
    return float('inf') if value != value else value


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true', help='10 min of gyro instead of 1 h')
    parser.add_argument(
        '--methods', nargs='+', default=['kalman', 'wavelet', 'iir', 'llr', 'none']
    )
    parser.add_argument('--repeat', type=int, default=None, help='rounds (default 3)')
    parser.add_argument(
        '--rest-learning', action='store_true', help='with bias learning at rest (core.rest)'
    )
    args = parser.parse_args()
    global REST
    REST = RestSettings(enabled=args.rest_learning)
    duration = 600.0 if args.quick else 3600.0
    repeat = args.repeat or (1 if args.quick else 3)
    s = streams(duration)
    print(
        f'# bench_core: {s["imu_t"].size} gyro messages at 100 Hz + '
        f'{int(duration)} temperatures at 1 Hz (after a {WARMUP_S / 60:.0f} min warm-up'
        f'{", rest learning on" if args.rest_learning else ""}); '
        f'{machine()}'
    )
    methods = ['floor', *args.methods]
    loop = dict.fromkeys(methods, float('inf'))
    replay_us = dict.fromkeys(methods, float('nan'))
    timed: dict[str, dict[str, float]] = {}
    for _ in range(repeat):  # round robin: load changes hit every method alike
        for method in methods:
            loop[method] = min(loop[method], run_loop(method, s, False)['loop'])
            run = run_loop(method, s, True)
            if method not in timed or run['p50'] < timed[method]['p50']:
                timed[method] = run
            if method != 'floor':
                replay_us[method] = min(replay_us[method], run_replay(method, s), key=_nan_last)
        print(f'  round {_ + 1}/{repeat} done', flush=True)
    floor = loop['floor']
    rows = [
        [
            method,
            loop[method],
            loop[method] / floor,
            loop[method] / GOAL_US,
            timed[method]['p50'],
            timed[method]['p99'],
            timed[method]['max'],
            timed[method]['temp_mean'],
            timed[method]['temp_max'],
            replay_us[method],
            replay_us[method] / loop[method],
        ]
        for method in methods
    ]
    print()
    headers = [
        'method',
        'loop us/msg',
        'x floor',
        'x goal (20 us)',
        'correct p50 us',
        'p99 us',
        'max us',
        'add_temperature mean us',
        'max us',
        'replay us/msg',
        'replay / loop',
    ]
    print(table(headers, rows))
    print()
    worst = max(r[1] for r in rows[1:])
    verdict = 'met' if worst <= GOAL_US else 'NOT met'
    print(f'goal <= {GOAL_US:g} us/msg one at a time: {verdict} (worst {worst:.2f} us)')


if __name__ == '__main__':
    main()
