"""Timing quirks of real drivers: what each costs the correction when only the stamps are off.

Run by hand (not in CI)::

    .venv/bin/python benchmarks/timing_quirks.py                      # ~12-16 min
    .venv/bin/python benchmarks/timing_quirks.py --plants 100 --quirks 'on change' 'temp late 5 s'

The simulator stamps every temperature reading and gyro message at a perfectly regular rate;
real drivers do not. Per plant (``default``: the simulator's default chamber, Imu 2 Hz,
temperature 1 Hz; a number: a drawn plant of the accuracy study,
:func:`fog_temp_comp.tools.plants.draw_plant`), seed 0, the runs of ``message_loss.py``: the
0.2 degC/min cycle (training), the 1 and 0.5 degC/min cycles and the -40 degC soak (replayed).
Each quirk (:data:`QUIRKS`, a fixed seed per quirk and run) changes the stamps only, the values
staying the simulated ones (but where it keeps fewer readings):

- ``temp jitter 20 ms`` / ``200 ms`` / ``40 %``: temperature stamped on receipt, Gaussian
  jitter or uniform within +-40 % of the sensor's interval, the stamps re-sorted (the readings
  keep their order);
- ``temp polled 5 s`` / ``30 s``: the driver polls a buffer and stamps all readings of a poll
  on receipt, 1 ms apart: several readings on almost one stamp, then a gap;
- ``temp rate / 4``: the sensor's rate drops to a quarter halfway through (every 4th reading);
- ``on change``: published only when the reading changes (the last kept one differs);
- ``temp late 0.5 s`` / ``5 s`` / ``early 5 s``: temperature stamps on a clock that far off the
  gyro's;
- ``imu jitter 5 ms``: gyro stamps jittered (Gaussian), re-sorted.

Two scenarios as in ``message_loss.py``: ``a``, the replayed runs have the quirk, ``calibrate``
(no flags) on the clean training run; ``b``, the training run has it too and ``calibrate`` runs
on it (:func:`~fog_temp_comp.core.model_choice.choose_and_calibrate`). ``on change`` has a
third, ``a+told`` (and so have the polls): scenario ``a`` with the clean calibration's
``temperature_period_s``, ``temperature_hold_s`` and ``temperature_spread_s`` set as
``calibrate`` measures them on the quirky training run (what a
user sets as the node's parameters when the chamber bags were recorded with another driver).

Figures as in ``message_loss.py`` (``accuracy.py``'s :func:`metrics`), each ``quirky / clean /
oracle`` on the same gyro messages (the quirky compensator's published ones, scored on their
true stamps): the median 10 s stability ratio after/before, the median 100 s stability after
(deg/h), the worst 10 s range ratio on the cycles and on the soak. ``100 s: quirky over clean``
is what the quirk costs. ``model``: the model ``calibrate`` chose in ``b`` (``=``: the clean
choice); ``period / hold / spread``: the ``temperature_period_s`` / ``temperature_hold_s`` /
``temperature_spread_s`` the replay used (``calibrate``'s in ``b``). ``warm-up``: the
longest over the replayed runs of the time (s) from the first temperature reading to the
compensator's estimator being ready (``never``: not within 2 h). ``counters``: the
compensator's counters, summed over the replayed runs, that differ from the clean replay's
(but the routine ones), the gyro's as a share of the gyro messages. The model choice runs in
one process (``FOG_TEMP_COMP_PROCESSES=1`` unless set otherwise).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time
import zlib
from collections.abc import Callable

import numpy as np
from message_loss import (
    baseline,
    calibrated,
    cells,
    counter_text,
    growth_percent,
    model_text,
    replayed,
    run_study,
    scored_alike,
)

from fog_temp_comp.core.coefficients import Coefficients
from fog_temp_comp.core.compensator import Compensator
from fog_temp_comp.core.publishing import with_reading_timing
from fog_temp_comp.tools.simulate import SimulatedRun

#: a timing quirk: the run as a quirky driver stamps it, from a generator
Quirk = Callable[[SimulatedRun, np.random.Generator], SimulatedRun]

#: the quirks' seed, with the quirk's name and the run's index
QUIRK_SEED = 37
#: readings of one poll are stamped this far apart, s
POLL_SPACING_S = 1e-3
#: the warm-up is looked for within this long of the first reading, s
WARM_UP_LIMIT_S = 7200.0


def interval_s(run: SimulatedRun) -> float:
    """The sensor's interval between readings, s."""
    return float(np.median(np.diff(run.temp_stamps_s)))


def with_temperature(run: SimulatedRun, stamps_s: np.ndarray, keep: np.ndarray) -> SimulatedRun:
    """``run`` with the readings where ``keep`` is true, at ``stamps_s`` (re-sorted)."""
    return dataclasses.replace(
        run,
        temp_stamps_s=np.sort(stamps_s[keep]),
        temperature_degC=run.temperature_degC[keep],
    )


def gaussian_jitter(sigma_s: float) -> Quirk:
    """Temperature stamps with Gaussian jitter of ``sigma_s`` s, re-sorted."""

    def quirk(run: SimulatedRun, rng: np.random.Generator) -> SimulatedRun:
        t = run.temp_stamps_s
        return with_temperature(run, t + rng.normal(0.0, sigma_s, t.size), np.ones(t.size, bool))

    return quirk


def uniform_jitter(fraction: float) -> Quirk:
    """Temperature stamps uniform within +-``fraction`` of the sensor's interval, re-sorted."""

    def quirk(run: SimulatedRun, rng: np.random.Generator) -> SimulatedRun:
        t = run.temp_stamps_s
        half_width_s = fraction * interval_s(run)
        jitter_s = rng.uniform(-half_width_s, half_width_s, t.size)
        return with_temperature(run, t + jitter_s, np.ones(t.size, bool))

    return quirk


def polled(poll_s: float) -> Quirk:
    """Readings delivered at polls every ``poll_s`` s (random phase), 1 ms apart in a poll."""

    def quirk(run: SimulatedRun, rng: np.random.Generator) -> SimulatedRun:
        t = run.temp_stamps_s
        phase_s = rng.uniform(0.0, poll_s)
        poll = np.ceil((t - phase_s) / poll_s)
        first = np.r_[True, poll[1:] != poll[:-1]]
        rank = np.arange(t.size) - np.maximum.accumulate(np.where(first, np.arange(t.size), 0))
        stamps_s = phase_s + poll * poll_s + POLL_SPACING_S * rank
        return with_temperature(run, stamps_s, np.ones(t.size, bool))

    return quirk


def rate_quartered(run: SimulatedRun, rng: np.random.Generator) -> SimulatedRun:
    """The sensor at its rate for the first half of the run, every 4th reading after."""
    t = run.temp_stamps_s
    second_half = t >= 0.5 * (t[0] + t[-1])
    keep = ~second_half | (np.arange(t.size) % 4 == 0)
    return with_temperature(run, t, keep)


def on_change(run: SimulatedRun, rng: np.random.Generator) -> SimulatedRun:
    """Readings published only when they differ from the last one published."""
    values = run.temperature_degC
    keep = np.r_[True, values[1:] != values[:-1]]
    return with_temperature(run, run.temp_stamps_s, keep)


def offset(offset_s: float) -> Quirk:
    """Temperature stamps ``offset_s`` s late (negative: early) against the gyro's."""

    def quirk(run: SimulatedRun, rng: np.random.Generator) -> SimulatedRun:
        t = run.temp_stamps_s
        return with_temperature(run, t + offset_s, np.ones(t.size, bool))

    return quirk


def gyro_jitter(sigma_s: float) -> Quirk:
    """Gyro stamps with Gaussian jitter of ``sigma_s`` s, re-sorted (the rates keep order)."""

    def quirk(run: SimulatedRun, rng: np.random.Generator) -> SimulatedRun:
        t = run.imu_stamps_s
        return dataclasses.replace(run, imu_stamps_s=np.sort(t + rng.normal(0, sigma_s, t.size)))

    return quirk


QUIRKS: dict[str, Quirk] = {
    'temp jitter 20 ms': gaussian_jitter(0.020),
    'temp jitter 200 ms': gaussian_jitter(0.200),
    'temp jitter 40 %': uniform_jitter(0.40),
    'temp polled 5 s': polled(5.0),
    'temp polled 30 s': polled(30.0),
    'temp rate / 4': rate_quartered,
    'on change': on_change,
    'temp late 0.5 s': offset(0.5),
    'temp late 5 s': offset(5.0),
    'temp early 5 s': offset(-5.0),
    'imu jitter 5 ms': gyro_jitter(0.005),
}


def quirky(run: SimulatedRun, quirk: str, index: int) -> SimulatedRun:
    """``run`` (the ``index``-th of the plan, 0: training) as the quirky driver stamps it."""
    rng = np.random.default_rng((QUIRK_SEED, zlib.crc32(quirk.encode()), index))
    return QUIRKS[quirk](run, rng)


def warm_up_s(run: SimulatedRun, coeffs: Coefficients) -> float:
    """Time (s) from the first reading to the estimator's being ready, messages fed in order.

    Gyro messages in too (they put back the held readings of a sensor published on change),
    up to :data:`WARM_UP_LIMIT_S` after the first reading (inf: not ready by then).
    """
    compensator = Compensator(coeffs.model, coeffs.denoise)
    first_s = float(run.temp_stamps_s[0])
    until_s = first_s + WARM_UP_LIMIT_S
    n_temp = int(np.searchsorted(run.temp_stamps_s, until_s))
    n_imu = int(np.searchsorted(run.imu_stamps_s, until_s))
    stamps_s = np.r_[run.temp_stamps_s[:n_temp], run.imu_stamps_s[:n_imu]]
    order = np.argsort(stamps_s, kind='stable')  # temperature first on equal stamps
    rates = run.rates_rad_s[:n_imu].tolist()
    temperature = run.temperature_degC[:n_temp].tolist()
    for k in order.tolist():
        if k < n_temp:
            compensator.add_temperature(float(stamps_s[k]), temperature[k])
        else:
            compensator.correct_xyz(float(stamps_s[k]), *rates[k - n_temp])
        if compensator.status.estimator_ready:
            return float(stamps_s[k]) - first_s
    return math.inf


def longest_warm_up_s(runs: dict[str, SimulatedRun], coeffs: Coefficients) -> str:
    """The longest warm-up over ``runs``, for the table."""
    longest = max(warm_up_s(r, coeffs) for r in runs.values())
    return 'never' if math.isinf(longest) else f'{longest:.0f} s'


def timing_text(coeffs: Coefficients) -> str:
    """``temperature_period_s / temperature_hold_s / temperature_spread_s`` of the coefficients."""
    d = coeffs.denoise
    return f'{d.temperature_period_s:g} / {d.temperature_hold_s:g} / {d.temperature_spread_s:g}'


def changed_counters(counters: dict[str, int], clean: dict[str, int]) -> dict[str, int]:
    """The counters that differ from the clean replay's (the others set to 0)."""
    return {k: v if v != clean.get(k, 0) else 0 for k, v in counters.items()}


#: the quirks that the node can be told of (its reading-timing parameters): scenario a+told
TOLD_QUIRKS = ('on change', 'temp polled 5 s', 'temp polled 30 s')


def with_timing(coeffs: Coefficients, train: SimulatedRun) -> Coefficients:
    """``coeffs`` with the reading timing ``calibrate`` measures on ``train``."""
    denoise = with_reading_timing(coeffs.denoise, [train.as_record()])
    return dataclasses.replace(coeffs, denoise=denoise)


def study_plant(plant: str, quirks: list[str], scenarios: list[str]) -> None:
    """Print the rows of one plant: clean, then each quirk and scenario."""
    started = time.perf_counter()
    base = baseline(plant)
    train, tests, coeffs, model = base.train, base.tests, base.coeffs, base.model
    clean_rad_s, clean_counters, every = base.clean_rad_s, base.clean_counters, base.every
    print(
        f'| {plant} | none | - | {model_text(model, base.lags)} | {timing_text(coeffs)} '
        f'| {cells(base.clean, base.clean, base.clean_oracle)} | - '
        f'| {longest_warm_up_s(tests, coeffs)} | {counter_text(clean_counters)} |',
        flush=True,
    )
    for quirk in quirks:
        changed = {n: quirky(r, quirk, k + 1) for k, (n, r) in enumerate(tests.items())}
        train_quirky = quirky(train, quirk, 0)
        for scenario in scenarios + (['a+told'] if quirk in TOLD_QUIRKS else []):
            used, name = coeffs, '='
            if scenario == 'b':
                used, chosen, chosen_lags = calibrated(train_quirky)
                name = model_text('=' if chosen == model else chosen, chosen_lags)
            elif scenario == 'a+told':
                used = with_timing(coeffs, train_quirky)
            quirky_rad_s, counters = replayed(changed, used)
            figures, alike, orc = scored_alike(tests, every, quirky_rad_s, clean_rad_s)
            print(
                f'| {plant} | {quirk} | {scenario} | {name} | {timing_text(used)} '
                f'| {cells(figures, alike, orc)} '
                f'| {growth_percent(figures["s100"], alike["s100"])} '
                f'| {longest_warm_up_s(changed, used)} '
                f'| {counter_text(changed_counters(counters, clean_counters))} |',
                flush=True,
            )
    print(f'(plant {plant}: {time.perf_counter() - started:.0f} s)', flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--plants', nargs='+', default=['100', '105', '900'])
    parser.add_argument('--quirks', nargs='+', choices=list(QUIRKS), default=list(QUIRKS))
    parser.add_argument('--scenarios', nargs='+', choices=('a', 'b'), default=['a', 'b'])
    args = parser.parse_args()
    header = (
        '| plant | quirk | scenario | model | period / hold / spread s '
        '| 10 s ratio: quirky / clean / oracle | 100 s deg/h | range cycles | range soaks '
        '| 100 s: quirky over clean | warm-up | counters |'
    )
    run_study(study_plant, header, args.plants, args.quirks, args.scenarios)


if __name__ == '__main__':
    main()
