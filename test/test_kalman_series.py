"""The model choice on two processes: half the Kalman series and half the scores in a fork.

:func:`~fog_temp_comp.core.kalman_series.prefetch_series` must give the same bits as one
process, and ``choose_and_calibrate`` (with
:func:`~fog_temp_comp.core.cross_validation.cross_validate_on_two`) the same scores and
coefficients either way. A fork needs
a process with no other thread, and the test process may hold some from earlier tests, so the
two-process cases run in a fresh interpreter.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fresh_interpreter import run_pickling

from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS
from fog_temp_comp.core.kalman_series import estimator_series, prefetch_series, series_cache
from fog_temp_comp.tools.simulate import SimulationConfig, simulate_run

from simdata import EIGHT_HOUR_CYCLE

FIELDS = ('stamp_s', 'temperature_degC', 'tdot_degC_per_min', 'tdot_std_degC_per_min', 'ready')

SCRIPT = """
import multiprocessing, pickle, sys
sys.path.insert(0, sys.argv[2])
from fog_temp_comp.core import cross_validation, kalman_series
from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS
from fog_temp_comp.core.model_choice import choose_and_calibrate
from fog_temp_comp.tools.simulate import simulate_run
from simdata import EIGHT_HOUR_CYCLE

records = [simulate_run('cycle', 0.2, EIGHT_HOUR_CYCLE, seed=3).as_record()]
estimators = [(0.001, 0.0), (0.003, 0.0), (0.001, 240.0), (0.003, 480.0), (0.001, 0.0)]
out = {}
with kalman_series.series_cache():
    out['child'] = kalman_series.prefetch_series(
        records, RECOMMENDED_SETTINGS, estimators, min_readings=0
    )
    out['series'] = [
        kalman_series.estimator_series(records, RECOMMENDED_SETTINGS, e) for e in estimators
    ]
    out['again'] = kalman_series.prefetch_series(
        records, RECOMMENDED_SETTINGS, estimators, min_readings=0
    )
with kalman_series.series_cache():
    out['short'] = kalman_series.prefetch_series(
        records, RECOMMENDED_SETTINGS, estimators, min_readings=10**6
    )
out['outside'] = kalman_series.prefetch_series(
    records, RECOMMENDED_SETTINGS, estimators, min_readings=0
)
forks = []
real_fork = kalman_series.ForkedCall
for module in (kalman_series, cross_validation):
    module.ForkedCall = lambda *args: forks.append(args[0].__name__) or real_fork(*args)
# one training run, then two runs (folds by run) with a held-out run to choose by
several = [simulate_run('cycle', 0.2, EIGHT_HOUR_CYCLE, seed=s).as_record() for s in (4, 5)]
heldout = [simulate_run('cycle', 0.4, EIGHT_HOUR_CYCLE, seed=6).as_record()]
for name, min_readings, training, chosen_by in (
    ('two', 0, records, []),
    ('one', 1 << 62, records, []),
    ('two_heldout', 0, several, heldout),
    ('one_heldout', 1 << 62, several, heldout),
):
    kalman_series.PARALLEL_MIN_READINGS = min_readings
    forks.clear()
    result, scores, chosen = choose_and_calibrate(
        training, RECOMMENDED_SETTINGS, heldout=chosen_by
    )
    out[name + '_forks'] = list(forks)
    out[name] = (
        result.coefficients.model.coefficients,
        [(s.structure, s.criterion, s.error, s.parts) for s in scores],
        chosen.structure,
    )


def in_pool_worker():
    from fog_temp_comp.core.forked import fork_available
    result, _, _ = choose_and_calibrate(records, RECOMMENDED_SETTINGS)
    return fork_available(), result.coefficients.model.coefficients


kalman_series.PARALLEL_MIN_READINGS = 0
with multiprocessing.get_context('fork').Pool(1) as pool:  # daemonic: may not fork again
    out['pool'] = pool.apply(in_pool_worker)
with open(sys.argv[1], 'wb') as file:
    pickle.dump(out, file)
"""


def run_script(tmp_path: Path) -> dict[str, Any]:
    """:data:`SCRIPT`'s results, from a fresh interpreter."""
    out = tmp_path / 'series.pickle'
    result, _ = run_pickling(SCRIPT, out, str(Path(__file__).parent), timeout_s=300.0)
    return dict(result)


def test_series_from_two_processes_are_one_process_bits(tmp_path: Path) -> None:
    """The child's half and the parent's equal the serial series; the choice is the same."""
    out = run_script(tmp_path)
    # four distinct estimators (one given twice): the child takes every other one
    assert out['child'] == 2
    assert out['again'] == 0  # all cached already
    assert out['short'] == 0  # 8 h at 1 Hz is under a million readings
    assert out['outside'] == 0  # no cache to fill outside series_cache()
    records = [simulate_run('cycle', 0.2, EIGHT_HOUR_CYCLE, seed=3).as_record()]
    estimators = [(0.001, 0.0), (0.003, 0.0), (0.001, 240.0), (0.003, 480.0), (0.001, 0.0)]
    for estimator, (forked,) in zip(estimators, out['series'], strict=True):
        (serial,) = estimator_series(records, RECOMMENDED_SETTINGS, estimator)
        for name in FIELDS:
            np.testing.assert_array_equal(getattr(forked, name), getattr(serial, name))
    # the filters, then the scores, on two processes
    assert out['two_forks'] == ['_computed', 'cross_validate']
    assert out['one_forks'] == []
    # with held-out runs, their series too
    assert out['two_heldout_forks'] == ['_computed', '_computed', 'cross_validate']
    assert out['one_heldout_forks'] == []
    for two, one in ((out['two'], out['one']), (out['two_heldout'], out['one_heldout'])):
        np.testing.assert_array_equal(two[0], one[0])
        assert two[1] == one[1]
        assert two[2] == one[2]
    # a multiprocessing Pool's worker (as the benchmarks run calibrate) works in one process
    assert out['pool'][0] is False
    np.testing.assert_array_equal(out['pool'][1], out['one'][0])


def test_prefetch_does_nothing_for_one_estimator() -> None:
    """One estimator (or the same one twice) is not worth a fork; the cache fills on demand."""
    cfg = SimulationConfig(imu_hz=0.5, temp_hz=1.0, cycle_soak_s=600.0)
    records = [simulate_run('cycle', 1.0, cfg, seed=1).as_record()]
    with series_cache():
        assert (
            prefetch_series(records, RECOMMENDED_SETTINGS, [(0.001, 0.0)] * 2, min_readings=0) == 0
        )
        first = estimator_series(records, RECOMMENDED_SETTINGS, (0.001, 0.0))
        again = estimator_series(records, RECOMMENDED_SETTINGS, (0.001, 0.0))
    assert first[0] is again[0]  # cached


def test_a_child_that_cannot_start_leaves_the_work_to_the_parent(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Out of processes (fork fails): no child, no error; the parent computes every series."""
    import multiprocessing.context

    from fog_temp_comp.core import forked, kalman_series

    def no_fork(self: object) -> None:
        raise OSError(11, 'Resource temporarily unavailable')

    monkeypatch.setattr(multiprocessing.context.ForkProcess, 'start', no_fork)
    monkeypatch.setattr(kalman_series, 'fork_available', lambda: True)
    with forked.ForkedCall(sum, [1, 2]) as child:
        assert child.result() is None
    records = [
        simulate_run('cycle', 1.0, SimulationConfig(cycle_soak_s=600.0), seed=1).as_record()
    ]
    estimators = [(0.001, 0.0), (0.003, 0.0)]
    with series_cache():
        assert prefetch_series(records, RECOMMENDED_SETTINGS, estimators, min_readings=0) == 0
        series = [estimator_series(records, RECOMMENDED_SETTINGS, e) for e in estimators]
    for estimator, (got,) in zip(estimators, series, strict=True):
        (expected,) = estimator_series(records, RECOMMENDED_SETTINGS, estimator)
        np.testing.assert_array_equal(got.tdot_degC_per_min, expected.tdot_degC_per_min)


def test_one_process_when_the_environment_asks(monkeypatch: pytest.MonkeyPatch) -> None:
    """FOG_TEMP_COMP_PROCESSES=1 keeps the model choice (and the bag read) in one process."""
    from fog_temp_comp.core import forked

    monkeypatch.setattr(forked.threading, 'active_count', lambda: 1)  # as in a fresh process
    monkeypatch.setattr(forked, '_daemonic', lambda: False)
    monkeypatch.setattr(forked.os, 'sched_getaffinity', lambda pid: {0, 1}, raising=False)
    monkeypatch.setattr(forked.sys, 'platform', 'linux')
    monkeypatch.delenv(forked.ONE_PROCESS_VARIABLE, raising=False)
    assert forked.fork_available()
    monkeypatch.setenv(forked.ONE_PROCESS_VARIABLE, '1')
    assert not forked.fork_available()
