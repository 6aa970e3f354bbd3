"""The fog-temp-comp command line, in-process on real bags and YAML files in tmp_path."""

from __future__ import annotations

import ast
import dataclasses
import io
import math
import os
import shutil
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from numpy.testing import assert_allclose, assert_array_equal
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Writer as Rosbag2Writer
from rosbags.rosbag2.enums import StoragePlugin
from rosbags.typesys import Stores, get_typestore

from fog_temp_comp.bag.bagio import (
    FORMATS,
    IMU_TYPE,
    TEMPERATURE_TYPE,
    BagWriter,
    bag_format,
    make_imu,
    make_temperature,
)
from fog_temp_comp.bag.stream import read_record
from fog_temp_comp.core.coefficients import load
from fog_temp_comp.core.compensator_types import CompensatorCounters, CompensatorStatus
from fog_temp_comp.core.denoise import METHODS
from fog_temp_comp.core.evaluate import compensate_record
from fog_temp_comp.core.model import PAPER_TERMS, coefficient_key
from fog_temp_comp.core.restfile import file_sha256, read_learned_bias
from fog_temp_comp.core.units import AXES, DEG_H_PER_RAD_S
from fog_temp_comp.tools import cli, commands
from fog_temp_comp.tools.evaluate_command import clamp_notes
from fog_temp_comp.tools.simulate import (
    TRUE_COEFFICIENTS,
    SimulatedRun,
    SimulationConfig,
    run_name,
    simulate_run,
    true_model,
)

from simdata import SHORT_CHAMBER, bag_path, write_run

REPO = Path(__file__).resolve().parents[1]
TDOT_KEY = coefficient_key('Tdot')
# a small chamber for the simulate command and the message-level compensate checks
SMALL = SimulationConfig(
    imu_hz=0.5,
    temp_hz=0.5,
    low_degC=15.0,
    high_degC=25.0,
    start_degC=20.0,
    cycle_soak_s=300.0,
    soak_duration_s=600.0,
)
STRING_TYPE = 'std_msgs/msg/String'


def plain_read(path: Path) -> dict[str, list[tuple[int, bytes, Any]]]:
    """(log ns, raw bytes, message) of every message, per topic, with a plain AnyReader loop."""
    out: dict[str, list[tuple[int, bytes, Any]]] = {}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for conn, log_ns, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            out.setdefault(conn.topic, []).append((log_ns, bytes(raw), msg))
    return out


def topic_types(path: Path) -> dict[str, str]:
    """Topic -> message type of a bag."""
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        return {name: info.msgtype for name, info in reader.topics.items()}


def stamp_ns(msg: Any) -> int:
    """Header stamp in integer nanoseconds."""
    return msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec


def rates_of(messages: Sequence[tuple[int, bytes, Any]]) -> np.ndarray:
    """Angular velocities (N, 3) of Imu messages."""
    return np.array(
        [
            (m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z)
            for _, _, m in messages
        ]
    )


def error_line(capsys: pytest.CaptureFixture[str]) -> str:
    """The single ``ERROR:`` line a failing command prints on stderr."""
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith('ERROR: ')
    return lines[0]


def write_streams(
    path: Path,
    fmt: str,
    run: SimulatedRun,
    imu_rates: dict[str, np.ndarray],
    *,
    rng: np.random.Generator | None = None,
    notes: bool = False,
) -> Path:
    """A chamber bag with several Imu topics (and optionally randomized non-gyro Imu fields).

    Topics are registered Imu first, then temperature, as :func:`write_chamber_bag` does; on
    equal stamps the temperature is written first.
    """
    imu_ns = np.round(run.imu_stamps_s * 1e9).astype(np.int64).tolist()
    temp_ns = np.round(run.temp_stamps_s * 1e9).astype(np.int64).tolist()
    string = get_typestore(Stores.ROS2_JAZZY).types[STRING_TYPE]
    events: list[tuple[int, int, str, Any]] = []
    for k, ns in enumerate(temp_ns):
        msg = make_temperature(ns, 'fog_link', run.temperature_degC[k])
        events.append((ns, 0, '/imu/temperature', msg))
    for topic, rates in imu_rates.items():
        for k, ns in enumerate(imu_ns):
            msg = make_imu(ns, 'fog_link', rates[k])
            if rng is not None:
                q = rng.normal(size=4)
                q /= np.linalg.norm(q)
                msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w = q
                msg.orientation_covariance = rng.uniform(0.0, 1e-3, 9)
                msg.angular_velocity_covariance = rng.uniform(0.0, 1e-9, 9)
                acc = rng.normal(0.0, 0.1, 3) + np.array([0.0, 0.0, 9.81])
                a = msg.linear_acceleration
                a.x, a.y, a.z = float(acc[0]), float(acc[1]), float(acc[2])
                msg.linear_acceleration_covariance = rng.uniform(0.0, 1e-4, 9)
            events.append((ns, 1, topic, msg))
    if notes:
        for k, ns in enumerate(imu_ns[::50]):
            events.append((ns, 2, '/notes', string(data=f'note {k}')))
    events.sort(key=lambda e: (e[0], e[1]))
    with BagWriter(path, fmt) as writer:
        for topic in imu_rates:
            writer.add_topic(topic, IMU_TYPE)
        writer.add_topic('/imu/temperature', TEMPERATURE_TYPE)
        if notes:
            writer.add_topic('/notes', STRING_TYPE)
        for ns, _, topic, msg in events:
            writer.write(topic, ns, msg)
    return path


# --------------------------------------------------------------------------------------------
# Shared bags and coefficient files
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope='module')
def data_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp('cli_data')


@pytest.fixture(scope='module')
def cal_bag(data_dir: Path, short_cycle: SimulatedRun) -> Path:
    return write_run(data_dir / 'cal_cycle', 'mcap', short_cycle)


@pytest.fixture(scope='module')
def fast_bag(data_dir: Path, short_cycle_fast: SimulatedRun) -> Path:
    return write_run(data_dir / 'fast_cycle', 'mcap', short_cycle_fast)


@pytest.fixture(scope='module')
def coeffs_yaml(data_dir: Path, cal_bag: Path) -> Path:
    path = data_dir / 'coeffs_wavelet.yaml'
    assert commands.calibrate_command([cal_bag], path, stdout=io.StringIO()) == 0
    return path


@pytest.fixture(scope='module')
def small_run() -> SimulatedRun:
    return simulate_run('cycle', 1.0, SMALL, seed=21)


# --------------------------------------------------------------------------------------------
# simulate
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize('fmt', FORMATS)
def test_simulate_command_writes_bags_truth_and_manifest(tmp_path: Path, fmt: str) -> None:
    out = tmp_path / 'sim'
    runs = [('cycle', 1.0), ('soak', 10.0)]
    stdout = io.StringIO()
    assert commands.simulate_command(out, runs=runs, config=SMALL, fmt=fmt, stdout=stdout) == 0

    manifest = yaml.safe_load((out / 'manifest.yaml').read_text())
    assert manifest['format'] == fmt
    assert (manifest['imu_hz'], manifest['temp_hz']) == (SMALL.imu_hz, SMALL.temp_hz)
    assert manifest['seed'] == 0
    for j, axis in enumerate(AXES):
        entry = manifest['true_coefficients'][axis]
        assert entry == {
            coefficient_key(t): float(TRUE_COEFFICIENTS[i, j]) for i, t in enumerate(PAPER_TERMS)
        }
    assert [r['name'] for r in manifest['runs']] == [run_name(k, s) for k, s in runs]
    assert [r['kind'] for r in manifest['runs']] == ['cycle', 'soak']
    assert manifest['runs'][0]['setpoint_degC_per_min'] == 1.0
    assert manifest['runs'][1]['setpoint_degC'] == 10.0
    assert len(stdout.getvalue().splitlines()) == len(runs)

    sigma_white = SMALL.arw_10s_deg_h * np.sqrt(10.0 * SMALL.imu_hz)
    sigma_total = np.hypot(sigma_white, SMALL.bias_instability_deg_h)
    for entry in manifest['runs']:
        bag = out / entry['bag']
        assert bag.exists()
        assert bag_format(bag) == fmt
        assert bag.name == (entry['name'] + '.bag' if fmt == 'ros1' else entry['name'])
        with np.load(out / entry['truth']) as npz:
            truth = {k: npz[k] for k in npz.files}
        stamps = truth['imu_stamps_s']
        assert entry['duration_s'] == pytest.approx(stamps[-1] - stamps[0], abs=1e-6)
        expected = true_model().drift_deg_h(
            truth['true_temperature_degC'], truth['true_tdot_degC_per_min']
        )
        assert_allclose(truth['true_drift_deg_h'], expected, rtol=1e-12, atol=1e-12)

        record = read_record(bag)
        assert_array_equal(record.imu_stamps_s, stamps)
        # gyro output = drift + white noise + Gauss-Markov bias: the residual std must match
        # the configured noise (N ~ 500-1000 samples: std of a sample std ~3 %; allow 25 %)
        residual = record.rates_rad_s * DEG_H_PER_RAD_S - truth['true_drift_deg_h']
        assert_allclose(residual.std(axis=0), sigma_total, rtol=0.25)
        # imu and temperature share the 0.5 Hz grid here, so the measured temperature is the
        # true one plus white noise and 1/16 degC quantization (6 sigma + half a quantum)
        assert_array_equal(record.temp_stamps_s, stamps)
        bound = 6 * SMALL.temp_noise_degC + SMALL.temp_quantum_degC / 2
        assert np.all(np.abs(record.temperature_degC - truth['true_temperature_degC']) <= bound)
        if entry['kind'] == 'soak':
            # the coil lags the chamber's small oscillation around the setpoint
            deviation = np.abs(truth['true_temperature_degC'] - entry['setpoint_degC'])
            assert deviation.max() <= SMALL.soak_oscillation_degC + 1e-9


def test_simulate_manifest_reports_the_simulated_coefficients(tmp_path: Path) -> None:
    # with other coefficients in the config, the manifest must describe what was simulated
    cfg = dataclasses.replace(SMALL, coefficients=2.0 * TRUE_COEFFICIENTS)
    out = tmp_path / 'sim'
    rc = commands.simulate_command(out, runs=[('cycle', 1.0)], config=cfg, stdout=io.StringIO())
    assert rc == 0
    manifest = yaml.safe_load((out / 'manifest.yaml').read_text())
    matrix = np.array(
        [[manifest['true_coefficients'][a][coefficient_key(t)] for a in AXES] for t in PAPER_TERMS]
    )
    with np.load(out / manifest['runs'][0]['truth']) as npz:
        drift = npz['true_drift_deg_h']
        regressors = np.stack(
            [
                np.ones_like(npz['true_temperature_degC']),
                npz['true_temperature_degC'],
                npz['true_tdot_degC_per_min'],
            ],
            axis=1,
        )
    assert_allclose(regressors @ matrix, drift, rtol=1e-12)


def test_simulate_parser() -> None:
    parser = cli.build_parser()
    argv = ['simulate', 'out', '--format', 'ros1', '--imu-hz', '2.5', '--temp-hz', '0.5']
    args = parser.parse_args([*argv, '--seed', '7'])
    assert (args.command, args.out_dir, args.fmt) == ('simulate', Path('out'), 'ros1')
    assert (args.imu_hz, args.temp_hz, args.seed) == (2.5, 0.5, 7)
    defaults = parser.parse_args(['simulate', 'out'])
    assert defaults.fmt == 'mcap'
    assert (defaults.imu_hz, defaults.temp_hz) == (
        SimulationConfig().imu_hz,
        SimulationConfig().temp_hz,
    )
    assert defaults.seed == 0
    for fmt in FORMATS:
        assert parser.parse_args(['simulate', 'o', '--format', fmt]).fmt == fmt
    with pytest.raises(SystemExit) as info:
        parser.parse_args(['simulate', 'out', '--format', 'ros2'])
    assert info.value.code == 2
    with pytest.raises(SystemExit):
        parser.parse_args(['simulate', 'out', '--imu-hz', 'fast'])


# --------------------------------------------------------------------------------------------
# calibrate
# --------------------------------------------------------------------------------------------


def tdot_tolerance(fit: dict[str, Any], axis: str, true_value: float) -> float:
    """Allowed |fitted - true| for a Tdot coefficient.

    The OLS standard errors assume independent residuals, but the residuals hold a Gauss-Markov
    bias (600 s correlation) and the denoised Tdot has correlated errors, so the real spread is a
    few times larger: 6 sigma. Residual Tdot noise attenuates the slope (errors in variables) and
    the causal IIR lags; both are systematic, a few percent of the value: 3 %.
    """
    return 6.0 * fit[axis]['standard_errors'][TDOT_KEY] + 0.03 * abs(true_value)


@pytest.mark.parametrize('method', METHODS)
def test_calibrate_each_denoise_method(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], cal_bag: Path, method: str
) -> None:
    out = tmp_path / 'coeffs.yaml'
    argv = ['calibrate', str(cal_bag), '-o', str(out), '--denoise', method, '--quiet']
    assert cli.main(argv) == 0
    assert capsys.readouterr().err == ''  # --quiet: no progress line
    coeffs = load(out)
    assert coeffs.denoise.method == method
    assert coeffs.model.terms == PAPER_TERMS
    assert coeffs.frame_id == 'imu_link'
    assert coeffs.provenance['bags'] == [str(cal_bag)]
    assert coeffs.provenance['gyro_topics'] == ['/imu/data_raw']
    t_range = coeffs.model.temperature_range_degC
    # bin means of the coil temperature stay inside the chamber's swing (+ sensor noise)
    assert (
        SHORT_CHAMBER.low_degC - 0.5 < t_range.low < t_range.high < SHORT_CHAMBER.high_degC + 0.5
    )
    assert t_range.high - t_range.low > 5.0
    tdot = coeffs.model.coefficient('Tdot')
    assert np.all(np.isfinite(tdot))
    if method == 'none':
        return
    for j, axis in enumerate(AXES):
        true_value = TRUE_COEFFICIENTS[2, j]
        assert abs(tdot[j] - true_value) <= tdot_tolerance(coeffs.fit, axis, true_value), axis


def test_raw_tdot_fit_is_attenuated(tmp_path: Path, cal_bag: Path) -> None:
    # noise in the raw Tdot regressor biases its coefficient towards zero (paper, Table 1)
    fitted = {}
    for method in ('wavelet', 'none'):
        out = tmp_path / f'{method}.yaml'
        assert cli.main(['calibrate', str(cal_bag), '-o', str(out), '--denoise', method]) == 0
        fitted[method] = load(out).model.coefficient('Tdot')
    assert abs(fitted['none'][0]) < abs(fitted['wavelet'][0])
    assert abs(fitted['none'][0]) < abs(TRUE_COEFFICIENTS[2, 0])


def test_calibrate_on_two_bags(tmp_path: Path, cal_bag: Path, fast_bag: Path) -> None:
    out = tmp_path / 'both.yaml'
    paper = ['--terms', 'const,T,Tdot']  # one fixed pipeline, so the rows can be compared
    assert cli.main(['calibrate', str(cal_bag), str(fast_bag), '-o', str(out), *paper]) == 0
    both = load(out)
    singles = []
    options = commands.CalibrateOptions(terms=('const', 'T', 'Tdot'))
    for bag in (cal_bag, fast_bag):
        path = tmp_path / f'{bag.name}.yaml'
        assert commands.calibrate_command([bag], path, options=options, stdout=io.StringIO()) == 0
        singles.append(load(path))
    assert both.provenance['bags'] == [str(cal_bag), str(fast_bag)]
    # the rows of both bags are stacked: counts add up and the calibrated range is the union
    for axis in AXES:
        assert both.fit[axis]['n_samples'] == sum(s.fit[axis]['n_samples'] for s in singles)
    t_ranges = [s.model.temperature_range_degC for s in singles]
    assert both.model.temperature_range_degC.low == min(r.low for r in t_ranges)
    assert both.model.temperature_range_degC.high == max(r.high for r in t_ranges)
    tdot = both.model.coefficient('Tdot')
    for j, axis in enumerate(AXES):
        true_value = TRUE_COEFFICIENTS[2, j]
        assert abs(tdot[j] - true_value) <= tdot_tolerance(both.fit, axis, true_value), axis


def test_calibrate_refuses_a_soak(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = simulate_run('soak', 20.0, SMALL, seed=3)
    bag = write_run(tmp_path / 'soak', 'mcap', run)
    out = tmp_path / 'coeffs.yaml'
    assert cli.main(['calibrate', str(bag), '-o', str(out), '--quiet']) == 1
    line = error_line(capsys)
    assert line.startswith('ERROR: term T is not identifiable: the 1 bag(s) together span T by')
    assert not out.exists()


def test_calibrate_with_several_imu_topics(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    short_cycle_fast: SimulatedRun,
    fast_bag: Path,
) -> None:
    rng = np.random.default_rng(8)
    other = rng.normal(0.0, 1e-6, short_cycle_fast.rates_rad_s.shape)
    bag = write_streams(
        tmp_path / 'two_imus',
        'mcap',
        short_cycle_fast,
        {'/imu/data_raw': other, '/fog/rate': short_cycle_fast.rates_rad_s},
    )
    out = tmp_path / 'coeffs.yaml'
    assert cli.main(['calibrate', str(bag), '-o', str(out)]) == 1
    line = error_line(capsys)
    assert '/imu/data_raw' in line
    assert '/fog/rate' in line
    assert '--gyro-topic' in line
    assert not out.exists()

    assert cli.main(['calibrate', str(bag), '-o', str(out), '--gyro-topic', 'fog/rate']) == 0
    coeffs = load(out)
    assert coeffs.provenance['gyro_topics'] == ['/fog/rate']
    # the same streams in a single-Imu bag give the very same fit
    reference = tmp_path / 'reference.yaml'
    assert commands.calibrate_command([fast_bag], reference, stdout=io.StringIO()) == 0
    assert coeffs.model.terms == load(reference).model.terms
    # (the bag is chunked otherwise, the 10 s sums are summed in another order: equal up to
    # rounding, amplified by the fit)
    assert_allclose(coeffs.model.coefficients, load(reference).model.coefficients, rtol=1e-9)


def calibrates_as_the_reference(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    bag: Path,
    reference_bag: Path,
    stream_topic: tuple[str, str],
) -> str:
    """``calibrate`` with no flag on ``bag``, which has more topics than ``reference_bag``.

    It reads ``stream_topic`` ((``'gyro'`` or ``'temperature'``, topic)), says so in one
    ``NOTE`` line, and fits what the reference bag (only the streams used) gives. Returns the
    line.
    """
    out = tmp_path / 'coeffs.yaml'
    assert cli.main(['calibrate', str(bag), '-o', str(out)]) == 0
    notes = [line for line in capsys.readouterr().err.splitlines() if 'NOTE' in line]
    assert len(set(notes)) == 1, notes
    coeffs = load(out)
    stream, topic = stream_topic
    assert coeffs.provenance[f'{stream}_topics'] == [topic]
    reference = tmp_path / 'reference.yaml'
    assert commands.calibrate_command([reference_bag], reference, stdout=io.StringIO()) == 0
    assert coeffs.model.terms == load(reference).model.terms
    # (the bag is chunked otherwise, the 10 s sums are summed in another order: equal up to
    # rounding, amplified by the fit)
    assert_allclose(coeffs.model.coefficients, load(reference).model.coefficients, rtol=1e-9)
    return notes[0]


@pytest.mark.parametrize('fmt', FORMATS)
def test_the_raw_rate_is_told_from_a_filters_output_by_its_rep145_name(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    short_cycle_fast: SimulatedRun,
    fast_bag: Path,
    coeffs_yaml: Path,
    fmt: str,
) -> None:
    """``/imu/data_raw`` beside ``/imu/data`` (a filter's or a compensator's output): no flag."""
    filtered = short_cycle_fast.rates_rad_s - 5e-6  # what a bias-estimating filter would give
    bag = write_streams(
        bag_path(tmp_path, 'both', fmt),
        fmt,
        short_cycle_fast,
        {'/imu/data': filtered, '/imu/data_raw': short_cycle_fast.rates_rad_s},
    )
    note = calibrates_as_the_reference(tmp_path, capsys, bag, fast_bag, ('gyro', '/imu/data_raw'))
    assert "using /imu/data_raw, the raw rate by the topics' names" in note
    assert 'not /imu/data;' in note

    out_bag = bag_path(tmp_path, 'out', fmt)
    argv = ['compensate', str(bag), '--coeffs', str(coeffs_yaml), '-o', str(out_bag)]
    assert cli.main(argv) == 0
    assert '/imu/data_raw_compensated' in capsys.readouterr().out
    written = plain_read(out_bag)
    assert_array_equal(rates_of(written['/imu/data']), filtered)  # copied as it was
    expected = compensate_record(read_record(fast_bag), load(coeffs_yaml))
    assert_allclose(rates_of(written['/imu/data_raw_compensated']), expected, rtol=1e-15, atol=0)


def write_with_chamber_air(
    path: Path, fmt: str, run: SimulatedRun, temp_topics: Sequence[str], imu_topic: str
) -> Path:
    """A chamber bag that also logs the chamber's air: ``temp_topics[0]`` is the gyro's sensor.

    The others carry the air, 3 degC warmer and a minute ahead of the sensor.
    """
    air = np.interp(run.temp_stamps_s + 60.0, run.temp_stamps_s, run.temperature_degC) + 3.0
    with BagWriter(path, fmt) as writer:
        for topic in temp_topics:
            writer.add_topic(topic, TEMPERATURE_TYPE)
        writer.add_topic(imu_topic, IMU_TYPE)
        events = [(t, 0, k) for k, t in enumerate(run.temp_stamps_s)]
        events += [(t, 1, k) for k, t in enumerate(run.imu_stamps_s)]
        for stamp_s, kind, k in sorted(events):
            ns = round(stamp_s * 1e9)
            if kind == 1:
                writer.write(imu_topic, ns, make_imu(ns, 'fog_link', run.rates_rad_s[k]))
                continue
            for j, topic in enumerate(temp_topics):
                value = run.temperature_degC[k] if j == 0 else air[k]
                writer.write(topic, ns, make_temperature(ns, 'fog_link', float(value)))
    return path


@pytest.mark.parametrize('fmt', FORMATS)
def test_the_gyros_temperature_is_told_from_the_chambers_by_its_namespace(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    short_cycle_fast: SimulatedRun,
    fast_bag: Path,
    coeffs_yaml: Path,
    fmt: str,
) -> None:
    """Gyro /fog/rate, temperatures /chamber/temperature and /fog/temperature: no flag needed."""
    bag = write_with_chamber_air(
        bag_path(tmp_path, 'with_air', fmt),
        fmt,
        short_cycle_fast,
        ['/fog/temperature', '/chamber/temperature'],
        '/fog/rate',
    )
    topic = ('temperature', '/fog/temperature')
    note = calibrates_as_the_reference(tmp_path, capsys, bag, fast_bag, topic)
    assert 'using /fog/temperature, beside /fog/rate' in note and '/chamber/temperature' in note

    out_bag = bag_path(tmp_path, 'out', fmt)
    argv = ['compensate', str(bag), '--coeffs', str(coeffs_yaml), '-o', str(out_bag)]
    assert cli.main(argv) == 0
    assert 'using /fog/temperature' in capsys.readouterr().err
    expected = compensate_record(read_record(fast_bag), load(coeffs_yaml))
    written = plain_read(out_bag)['/fog/rate_compensated']  # beside the gyro it corrects
    assert_allclose(rates_of(written), expected, rtol=1e-15, atol=0)


@pytest.mark.parametrize(
    'temp_topics',
    [['/a/temperature', '/b/temperature'], ['/fog/a/temperature', '/fog/b/temperature']],
)
def test_temperatures_that_the_namespace_does_not_tell_apart_are_each_calibrated_on(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    short_cycle_fast: SimulatedRun,
    temp_topics: list[str],
) -> None:
    """Each topic gets the model choice; the better score is kept and named in the YAML.

    (Before, calibrate refused; with ``--terms`` it still does: ``test_temperature_sources``.)
    """
    bag = write_with_chamber_air(
        tmp_path / 'two', 'mcap', short_cycle_fast, temp_topics, '/fog/rate'
    )
    out = tmp_path / 'coeffs.yaml'
    assert cli.main(['calibrate', str(bag), '-o', str(out)]) == 0
    sources = yaml.safe_load(out.read_text())['provenance']['selection']['temperature_sources']
    scores = {s['topic']: s['criterion'] for s in sources['sources']}
    assert list(scores) == sorted(temp_topics)
    # the first by name within the tolerance (2 %) of the best score
    best = next(t for t in scores if scores[t] <= min(scores.values()) * 1.02)
    assert sources['chosen'] == best and load(out).temperature_topic == best
    assert f'{best} ' in capsys.readouterr().out


@pytest.mark.parametrize('command', ['calibrate', 'compensate', 'evaluate'])
def test_command_output_follows_sys_stdout(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    cal_bag: Path,
    coeffs_yaml: Path,
    small_run: SimulatedRun,
    command: str,
) -> None:
    # the summary must go to the sys.stdout of the call (capsys, contextlib.redirect_stdout)
    if command == 'calibrate':
        target = tmp_path / 'c.yaml'
        argv = ['calibrate', str(cal_bag), '-o', str(target), '--quiet']
    elif command == 'compensate':
        target = tmp_path / 'out'
        bag = write_run(tmp_path / 'in', 'mcap', small_run)
        argv = ['compensate', str(bag), '--coeffs', str(coeffs_yaml), '-o', str(target)]
    else:
        target = cal_bag
        argv = ['evaluate', str(cal_bag), '--coeffs', str(coeffs_yaml)]
    assert cli.main(argv) == 0
    captured = capsys.readouterr()
    assert captured.err == ''
    assert target.name in captured.out


# --------------------------------------------------------------------------------------------
# compensate
# --------------------------------------------------------------------------------------------

IMU_FIELDS = (
    'orientation_covariance',
    'angular_velocity_covariance',
    'linear_acceleration_covariance',
)


@pytest.mark.parametrize('fmt', FORMATS)
def test_compensate_output_bag(
    tmp_path: Path, coeffs_yaml: Path, small_run: SimulatedRun, fmt: str
) -> None:
    rng = np.random.default_rng(99)
    in_bag = write_streams(
        bag_path(tmp_path, 'in', fmt),
        fmt,
        small_run,
        {'/imu/data_raw': small_run.rates_rad_s},
        rng=rng,
        notes=True,
    )
    out_bag = bag_path(tmp_path, 'out', fmt)
    argv = ['compensate', str(in_bag), '--coeffs', str(coeffs_yaml), '-o', str(out_bag)]
    assert cli.main(argv) == 0
    assert bag_format(out_bag) == fmt

    src, dst = plain_read(in_bag), plain_read(out_bag)
    assert set(dst) == {*src, '/imu/data'}
    assert topic_types(out_bag) == {**topic_types(in_bag), '/imu/data': IMU_TYPE}
    for topic, messages in src.items():
        # every input message copied untouched, at its log time
        assert [(t, raw) for t, raw, _ in dst[topic]] == [(t, raw) for t, raw, _ in messages]

    raw_in, corrected = src['/imu/data_raw'], dst['/imu/data']
    assert len(corrected) == len(raw_in) == small_run.imu_stamps_s.size
    assert [t for t, _, _ in corrected] == [t for t, _, _ in raw_in]
    assert [stamp_ns(m) for _, _, m in corrected] == [stamp_ns(m) for _, _, m in raw_in]
    assert {m.header.frame_id for _, _, m in corrected} == {'fog_link'}
    for (_, _, a), (_, _, b) in zip(raw_in, corrected, strict=True):
        for name in IMU_FIELDS:
            assert_array_equal(getattr(b, name), getattr(a, name))
        for vec in ('orientation', 'linear_acceleration'):
            va, vb = getattr(a, vec), getattr(b, vec)
            assert [getattr(vb, c) for c in 'xyzw' if hasattr(vb, c)] == [
                getattr(va, c) for c in 'xyzw' if hasattr(va, c)
            ]

    # the subtracted correction is the modelled drift: on average it matches the simulator's
    # true drift to within a few hundredths of a deg/h (fit standard errors ~0.003 deg/h, plus
    # the online filter's start-up); the drift itself is ~10 deg/h on x
    removed = (rates_of(raw_in) - rates_of(corrected)) * DEG_H_PER_RAD_S
    assert_allclose(removed.mean(axis=0), small_run.true_drift_deg_h.mean(axis=0), atol=0.05)


@pytest.mark.parametrize('fmt', FORMATS)
def test_compensate_matches_the_offline_core(
    tmp_path: Path, coeffs_yaml: Path, short_cycle_fast: SimulatedRun, fmt: str
) -> None:
    in_bag = write_run(bag_path(tmp_path, 'in', fmt), fmt, short_cycle_fast)
    out_bag = bag_path(tmp_path, 'out', fmt)
    argv = ['compensate', str(in_bag), '--coeffs', str(coeffs_yaml), '-o', str(out_bag)]
    assert cli.main(argv) == 0
    expected = compensate_record(read_record(in_bag), load(coeffs_yaml))
    got = rates_of(plain_read(out_bag)['/imu/data'])
    assert got.shape == expected.shape
    assert_allclose(got, expected, rtol=1e-15, atol=0.0)


@pytest.mark.parametrize('fmt', ['mcap', 'sqlite3'])
def test_a_file_compressed_bag_is_read_like_its_plain_copy(
    tmp_path: Path, short_cycle_fast: SimulatedRun, fmt: str
) -> None:
    """A bag recorded with ``--compression-mode file`` reads like its plain copy.

    ``ros2 bag record`` then keeps ``run.db3.zstd`` / ``run.mcap.zstd``: calibrate, compensate
    and evaluate give the same results (compensate once refused it: "not a recognised bag").
    """
    plain = write_run(tmp_path / 'plain' / 'run', fmt, short_cycle_fast)
    packed = write_run(tmp_path / 'packed' / 'run', fmt, short_cycle_fast, compress_file=True)
    assert [f.suffixes for f in packed.iterdir() if f.name != 'metadata.yaml'] == [
        ['.' + ('db3' if fmt == 'sqlite3' else fmt), '.zstd']
    ]
    assert bag_format(packed) == fmt
    tables, outputs = [], []
    for bag in (plain, packed):
        coeffs = bag.parent / 'coeffs.yaml'
        assert cli.main(['calibrate', str(bag), '-o', str(coeffs), '--terms', 'const,T,Tdot']) == 0
        out = bag.parent / 'out'
        assert cli.main(['compensate', str(bag), '--coeffs', str(coeffs), '-o', str(out)]) == 0
        assert bag_format(out) == fmt
        outputs.append(rates_of(plain_read(out)['/imu/data']))
        text = io.StringIO()
        assert commands.evaluate_command([bag], coeffs, stdout=text) == 0
        tables.append(text.getvalue())
    models = [load(bag.parent / 'coeffs.yaml').model for bag in (plain, packed)]
    assert models[1].terms == models[0].terms
    assert_array_equal(models[1].coefficients, models[0].coefficients)
    assert_array_equal(outputs[1], outputs[0])
    assert tables[1] == tables[0]


@pytest.mark.parametrize('fill', [0.0, math.nan])
def test_a_one_axis_gyro_with_zero_channels_is_calibrated_compensated_and_evaluated(
    tmp_path: Path,
    short_cycle_fast: SimulatedRun,
    capsys: pytest.CaptureFixture[str],
    fill: float,
) -> None:
    """A one-axis FOG's driver fills x and y with 0 or NaN: no correction and no ratio there.

    ``evaluate`` once stopped with a ZeroDivisionError traceback where they were 0; where they
    were NaN, ``calibrate`` dropped every sample ("stamps do not overlap").
    """
    rates = short_cycle_fast.rates_rad_s.copy()
    rates[:, :2] = fill
    bag = write_run(
        tmp_path / 'one_axis', 'mcap', dataclasses.replace(short_cycle_fast, rates_rad_s=rates)
    )
    coeffs = tmp_path / 'coeffs.yaml'
    assert cli.main(['calibrate', str(bag), '-o', str(coeffs)]) == 0
    captured = capsys.readouterr()
    assert 'R2=- (the rate never changes)' in captured.out and 'nan' not in captured.out
    nan_warning = 'no finite gyro rate on axis x, y (NaN throughout'
    assert (nan_warning in captured.err) == math.isnan(fill)
    loaded = load(coeffs)
    assert ('axes_without_finite_rate' in loaded.provenance) == math.isnan(fill)
    assert_array_equal(loaded.model.coefficients[:, :2], 0.0)
    assert np.all(loaded.model.coefficients[:2, 2] != 0.0)  # z's const and T
    corrected = tmp_path / 'out'
    assert cli.main(['compensate', str(bag), '--coeffs', str(coeffs), '-o', str(corrected)]) == 0
    out_rates = rates_of(plain_read(corrected)['/imu/data'])
    assert_array_equal(out_rates[:, :2], fill)  # passed on as they came
    assert np.isfinite(out_rates[:, 2]).all()
    capsys.readouterr()
    assert cli.main(['evaluate', str(bag), '--coeffs', str(coeffs)]) == 0
    rows = [line.split() for line in capsys.readouterr().out.splitlines()]
    ratios = {(row[1], row[2]): (row[5], row[8]) for row in rows if row[:1] == ['one_axis']}
    assert len(ratios) == 6
    for tau in ('10', '100'):
        assert ratios['x', tau] == ratios['y', tau] == ('-', '-')
        assert 0.0 < float(ratios['z', tau][0]) < 1.0  # z's drift is corrected


def test_compensate_rest_learning_removes_a_turn_on_shift(
    tmp_path: Path,
    coeffs_yaml: Path,
    short_cycle_fast: SimulatedRun,
    capsys: pytest.CaptureFixture[str],
) -> None:
    # the chamber unit never moves: with learning on, the shift since calibration is learned
    shift_deg_h = np.array([2.0, -1.5, 1.0])
    run = dataclasses.replace(
        short_cycle_fast, rates_rad_s=short_cycle_fast.rates_rad_s + shift_deg_h / DEG_H_PER_RAD_S
    )
    in_bag = write_run(tmp_path / 'in', 'mcap', run)
    out = {}
    for learn in (False, True):
        out_bag = tmp_path / f'out_{learn}'
        argv = ['compensate', str(in_bag), '--coeffs', str(coeffs_yaml), '-o', str(out_bag)]
        assert cli.main(argv + (['--rest-learning'] if learn else [])) == 0
        out[learn] = rates_of(plain_read(out_bag)['/imu/data'])
    assert 'rest learning:' in capsys.readouterr().out
    removed_deg_h = (out[False] - out[True]) * DEG_H_PER_RAD_S
    assert_array_equal(removed_deg_h[:100], 0.0)  # Tdot filter still warming up: untouched
    assert_allclose(removed_deg_h[-600:].mean(axis=0), shift_deg_h, atol=0.3)

    # the learned bias kept for the next replay: applied from the first corrected message on
    learned = tmp_path / 'learned_bias.yaml'
    base = ['compensate', str(in_bag), '--coeffs', str(coeffs_yaml), '--rest-learning']
    assert cli.main([*base, '-o', str(tmp_path / 'a'), '--rest-bias-out', str(learned)]) == 0
    saved = read_learned_bias(learned)
    assert_allclose(saved.bias_deg_h, shift_deg_h, atol=0.3)
    assert saved.coefficients_sha256 == file_sha256(coeffs_yaml)
    assert cli.main([*base, '-o', str(tmp_path / 'b'), '--rest-bias-in', str(learned)]) == 0
    assert 'rest learning: starting from' in capsys.readouterr().out
    started = (out[False] - rates_of(plain_read(tmp_path / 'b')['/imu/data'])) * DEG_H_PER_RAD_S
    first = int(np.argmax(np.any(out[False] != rates_of(plain_read(in_bag)['/imu/data_raw']), 1)))
    assert_allclose(started[first], saved.bias_deg_h, rtol=1e-9)  # from the first correction
    assert_allclose(started[-600:].mean(axis=0), shift_deg_h, atol=0.3)

    # refused: the file of other coefficients, or without --rest-learning
    other = tmp_path / 'other.yaml'
    other.write_text(coeffs_yaml.read_text() + '# recalibrated\n')
    argv = ['compensate', str(in_bag), '--coeffs', str(other), '--rest-learning']
    assert cli.main([*argv, '-o', str(tmp_path / 'c'), '--rest-bias-in', str(learned)]) == 1
    assert 'learned with other coefficients' in capsys.readouterr().err
    argv = ['compensate', str(in_bag), '--coeffs', str(coeffs_yaml), '-o', str(tmp_path / 'd')]
    assert cli.main([*argv, '--rest-bias-out', str(learned)]) == 1
    assert 'need --rest-learning' in capsys.readouterr().err
    assert not (tmp_path / 'c').exists() and not (tmp_path / 'd').exists()


def copy_prefix(src: Path, dst: Path, cut_ns: int) -> int:
    """Copy the messages logged before ``cut_ns`` into a new MCAP bag; return how many."""
    store = get_typestore(Stores.ROS2_JAZZY)
    count = 0
    with AnyReader([src], default_typestore=store) as reader:
        writer = Rosbag2Writer(dst, version=9, storage_plugin=StoragePlugin.MCAP)
        with writer:
            conns = {
                c.id: writer.add_connection(c.topic, c.msgtype, typestore=store)
                for c in reader.connections
            }
            for conn, log_ns, raw in reader.messages():
                if log_ns < cut_ns:
                    writer.write(conns[conn.id], log_ns, raw)
                    count += 1
    return count


@pytest.mark.parametrize('method', ['wavelet', 'iir'])
def test_compensate_is_causal(
    tmp_path: Path, coeffs_yaml: Path, fast_bag: Path, short_cycle_fast: SimulatedRun, method: str
) -> None:
    stamps = short_cycle_fast.imu_stamps_s
    # mid-record, on a ramp, between two samples and not on a 10 s grid boundary
    cut_s = stamps[0] + 0.55 * (stamps[-1] - stamps[0]) + 3.5
    cut_bag = tmp_path / 'cut'
    n_copied = copy_prefix(fast_bag, cut_bag, round(cut_s * 1e9))
    assert 0 < n_copied < 2 * stamps.size

    outputs = {}
    for name, bag in (('full', fast_bag), ('cut', cut_bag)):
        out = tmp_path / f'out_{name}'
        argv = ['compensate', str(bag), '--coeffs', str(coeffs_yaml), '-o', str(out)]
        assert cli.main([*argv, '--denoise', method]) == 0
        outputs[name] = plain_read(out)['/imu/data']
    full, cut = outputs['full'], outputs['cut']
    assert len(cut) == int(np.sum(stamps < cut_s))
    assert 0 < len(cut) < len(full)
    assert [stamp_ns(m) for _, _, m in cut] == [stamp_ns(m) for _, _, m in full[: len(cut)]]
    assert_array_equal(rates_of(cut), rates_of(full[: len(cut)]))


def test_compensate_denoise_override(
    tmp_path: Path, coeffs_yaml: Path, small_run: SimulatedRun
) -> None:
    bag = write_run(tmp_path / 'in', 'mcap', small_run)
    outputs = {}
    for method in ('wavelet', 'iir'):
        out = tmp_path / f'out_{method}'
        argv = ['compensate', str(bag), '--coeffs', str(coeffs_yaml), '-o', str(out)]
        assert cli.main([*argv, '--denoise', method]) == 0
        outputs[method] = rates_of(plain_read(out)['/imu/data'])
        coeffs = load(coeffs_yaml)
        record = read_record(bag)
        settings = commands.effective_settings(coeffs, method)
        assert settings.method == method
        assert_allclose(outputs[method], compensate_record(record, coeffs, settings), rtol=1e-15)
    assert not np.array_equal(outputs['wavelet'], outputs['iir'])


def test_compensate_refuses_an_existing_output(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], coeffs_yaml: Path, small_run: SimulatedRun
) -> None:
    bag = write_run(tmp_path / 'in', 'mcap', small_run)
    out = tmp_path / 'taken'
    out.mkdir()
    (out / 'keep.txt').write_text('precious\n')
    assert cli.main(['compensate', str(bag), '--coeffs', str(coeffs_yaml), '-o', str(out)]) == 1
    line = error_line(capsys)
    assert str(out) in line
    assert 'exists' in line
    assert [p.name for p in out.iterdir()] == ['keep.txt']
    assert (out / 'keep.txt').read_text() == 'precious\n'


def test_calibrate_refuses_an_existing_output_before_reading_any_bag(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The refusal comes first: the bag named here does not even exist."""
    out = tmp_path / 'c.yaml'
    out.write_text('mine\n')
    assert cli.main(['calibrate', str(tmp_path / 'no_such_bag'), '-o', str(out)]) == 1
    line = error_line(capsys)
    assert str(out) in line and 'exists already' in line and 'no_such_bag' not in line
    assert out.read_text() == 'mine\n'


@pytest.mark.parametrize('topic', ['/imu/data_raw', 'imu/temperature'])
def test_compensate_refuses_an_existing_output_topic(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    coeffs_yaml: Path,
    small_run: SimulatedRun,
    topic: str,
) -> None:
    bag = write_run(tmp_path / 'in', 'mcap', small_run)
    out = tmp_path / 'out'
    argv = ['compensate', str(bag), '--coeffs', str(coeffs_yaml), '-o', str(out)]
    assert cli.main([*argv, '--output-topic', topic]) == 1
    line = error_line(capsys)
    assert '--output-topic' in line
    assert '/' + topic.lstrip('/') in line
    assert not out.exists()


@pytest.mark.parametrize('fmt', FORMATS)
def test_compensate_of_a_raw_rate_on_imu_data_writes_beside_it(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    coeffs_yaml: Path,
    short_cycle_fast: SimulatedRun,
    fmt: str,
) -> None:
    """A driver that publishes its raw rate on /imu/data: no flag needed, the input kept."""
    in_bag = bag_path(tmp_path, 'in', fmt)
    write_run(in_bag, fmt, short_cycle_fast, imu_topic='/imu/data')
    out_bag = bag_path(tmp_path, 'out', fmt)
    argv = ['compensate', str(in_bag), '--coeffs', str(coeffs_yaml), '-o', str(out_bag)]
    assert cli.main(argv) == 0
    out = capsys.readouterr().out
    assert 'NOTE:' not in out  # the default for a gyro topic not named data_raw
    assert 'Imu on /imu/data_compensated:' in out
    assert topic_types(out_bag) == {**topic_types(in_bag), '/imu/data_compensated': IMU_TYPE}
    messages = plain_read(out_bag)
    expected = compensate_record(read_record(in_bag), load(coeffs_yaml))
    assert_allclose(rates_of(messages['/imu/data_compensated']), expected, rtol=1e-15, atol=0)
    assert_array_equal(rates_of(messages['/imu/data']), short_cycle_fast.rates_rad_s)
    # named by hand, the same topic is still refused
    again = bag_path(tmp_path, 'again', fmt)
    assert cli.main([*argv[:-1], str(again), '--output-topic', '/imu/data']) == 1
    assert '--output-topic /imu/data: already in' in error_line(capsys)
    assert not again.exists()
    # the output read again with no flag: its raw rate, not the compensated one beside it
    tables = []
    for bag in (out_bag, in_bag):
        assert cli.main(['evaluate', str(bag), '--coeffs', str(coeffs_yaml)]) == 0
        captured = capsys.readouterr()
        rows = [r.split()[1:] for r in captured.out.splitlines() if r.split()[:1] == [bag.name]]
        tables.append((rows, captured.err))
    assert len(tables[0][0]) == 6 and tables[0][0] == tables[1][0]
    assert 'using /imu/data, the raw rate' in tables[0][1]
    assert 'not /imu/data_compensated' in tables[0][1]


def test_compensate_custom_output_topic(
    tmp_path: Path, coeffs_yaml: Path, small_run: SimulatedRun
) -> None:
    bag = write_run(tmp_path / 'in', 'sqlite3', small_run)
    out = tmp_path / 'out'
    argv = ['compensate', str(bag), '--coeffs', str(coeffs_yaml), '-o', str(out)]
    assert cli.main([*argv, '--output-topic', 'fog/corrected']) == 0
    assert topic_types(out) == {**topic_types(bag), '/fog/corrected': IMU_TYPE}


def test_compensate_missing_coefficients(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], small_run: SimulatedRun
) -> None:
    bag = write_run(tmp_path / 'in', 'mcap', small_run)
    missing = tmp_path / 'no_such_coeffs.yaml'
    out = tmp_path / 'out'
    assert cli.main(['compensate', str(bag), '--coeffs', str(missing), '-o', str(out)]) == 1
    assert str(missing) in error_line(capsys)
    assert not out.exists()


@pytest.mark.parametrize(
    'key', ['axes.y.dtdot_deg_h_per_degC_per_min', 'calibrated_range', 'denoise', 'terms']
)
def test_compensate_malformed_coefficients(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    coeffs_yaml: Path,
    small_run: SimulatedRun,
    key: str,
) -> None:
    data = yaml.safe_load(coeffs_yaml.read_text())
    *parents, last = key.split('.')
    node = data
    for part in parents:
        node = node[part]
    del node[last]
    bad = tmp_path / 'bad.yaml'
    bad.write_text(yaml.safe_dump(data))
    bag = write_run(tmp_path / 'in', 'mcap', small_run)
    out = tmp_path / 'out'
    assert cli.main(['compensate', str(bag), '--coeffs', str(bad), '-o', str(out)]) == 1
    line = error_line(capsys)
    assert str(bad) in line
    assert key in line
    assert 'missing' in line
    assert not out.exists()


@pytest.mark.parametrize('fmt', ['mcap', 'ros1'])
def test_compensate_truncated_input(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    coeffs_yaml: Path,
    small_run: SimulatedRun,
    fmt: str,
) -> None:
    bag = write_run(bag_path(tmp_path, 'in', fmt), fmt, small_run)
    file = bag if fmt == 'ros1' else next(bag.glob('*.mcap'))
    os.truncate(file, file.stat().st_size // 2)
    out = bag_path(tmp_path, 'out', fmt)
    argv = ['compensate', str(bag), '--coeffs', str(coeffs_yaml), '-o', str(out)]
    assert cli.main([*argv, '--strict']) == 1  # (without: MCAP is copied as far as intact)
    assert str(bag) in error_line(capsys)
    assert not out.exists()


# --------------------------------------------------------------------------------------------
# evaluate
# --------------------------------------------------------------------------------------------


def parse_table(text: str) -> dict[tuple[str, str, float], list[float]]:
    """Rows of the evaluate table keyed by (run, axis, tau): the seven numeric columns."""
    lines = text.strip().splitlines()
    assert lines[0].split()[:3] == ['run', 'axis', 'tau_s']
    assert set(lines[1]) == {'-'}
    # the table ends with its unit line; only notes on the range guard may follow
    end = next(k for k, line in enumerate(lines) if line.startswith('(deg/h'))
    assert all(line.startswith('note: ') for line in lines[end + 1 :])
    rows = {}
    for line in lines[2:end]:
        run, axis, tau, *values = line.split()
        assert len(values) == 6
        rows[run, axis, float(tau)] = [float(v) for v in values]
    assert len(rows) == end - 2
    return rows


def stability_of(stamps: np.ndarray, rates_rad_s: np.ndarray, tau: float) -> np.ndarray:
    """Std (ddof 1) of consecutive tau-s means, for a gapless record whose length is a multiple."""
    per_window = round(tau / float(np.median(np.diff(stamps))))
    assert rates_rad_s.shape[0] % per_window == 0
    means = (rates_rad_s * DEG_H_PER_RAD_S).reshape(-1, per_window, 3).mean(axis=1)
    return means.std(axis=0, ddof=1)


def test_evaluate_table(cal_bag: Path, fast_bag: Path, coeffs_yaml: Path) -> None:
    stdout = io.StringIO()
    rc = commands.evaluate_command([fast_bag, cal_bag], coeffs_yaml, stdout=stdout)
    assert rc == 0
    rows = parse_table(stdout.getvalue())
    taus = (10.0, 100.0)
    assert set(rows) == {
        (bag.name, axis, tau) for bag in (fast_bag, cal_bag) for axis in AXES for tau in taus
    }
    record = read_record(fast_bag)
    for tau in taus:
        before = stability_of(record.imu_stamps_s, record.rates_rad_s, tau)
        for j, axis in enumerate(AXES):
            stab_before, stab_after, ratio, *_ = rows[fast_bag.name, axis, tau]
            assert stab_before == pytest.approx(before[j], abs=6e-5)  # printed to 4 decimals
            assert ratio == pytest.approx(stab_after / stab_before, abs=0.01)
    # held-out run (1 degC/min) with coefficients from the 0.5 degC/min run: drift removed
    for axis in AXES:
        stab_before, stab_after, *_ = rows[fast_bag.name, axis, 10.0]
        assert stab_after < stab_before, axis


def test_evaluate_tells_bags_of_one_name_apart(
    tmp_path: Path, cal_bag: Path, fast_bag: Path, coeffs_yaml: Path
) -> None:
    """Two units' cycle_1 in one table: each row says which (their folders), not cycle_1 twice."""
    a = shutil.copytree(cal_bag, tmp_path / 'u1' / 'cycle_1')
    b = shutil.copytree(fast_bag, tmp_path / 'u2' / 'cycle_1')
    stdout = io.StringIO()
    assert commands.evaluate_command([a, b, fast_bag], coeffs_yaml, stdout=stdout) == 0
    rows = parse_table(stdout.getvalue())
    assert {name for name, _, _ in rows} == {'u1/cycle_1', 'u2/cycle_1', 'fast_cycle'}
    # the same figures as the bag alone under its own name
    alone = io.StringIO()
    assert commands.evaluate_command([fast_bag], coeffs_yaml, stdout=alone) == 0
    single = parse_table(alone.getvalue())
    assert rows['u2/cycle_1', 'x', 10.0] == single['fast_cycle', 'x', 10.0]


def test_a_topic_missing_from_one_of_several_bags_is_named_with_that_bag(
    tmp_path: Path, fast_bag: Path, coeffs_yaml: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``evaluate A B --gyro-topic T`` where B lacks T: the error says B, not just 'bag'."""
    other = write_run(tmp_path / 'other', 'mcap', read_record(fast_bag), imu_topic='/fog/rate')
    argv = ['evaluate', str(fast_bag), str(other), '--coeffs', str(coeffs_yaml)]
    assert cli.main([*argv, '--gyro-topic', '/imu/data_raw']) == 1
    err = capsys.readouterr().err
    assert f'ERROR: {other}: --gyro-topic /imu/data_raw: not in bag; topics: ' in err


def test_evaluate_cli(
    capsys: pytest.CaptureFixture[str], fast_bag: Path, coeffs_yaml: Path
) -> None:
    assert cli.main(['evaluate', str(fast_bag), '--coeffs', str(coeffs_yaml)]) == 0
    assert capsys.readouterr().err == ''


def test_evaluate_extrapolates_tdot_by_default_and_clamps_when_asked(
    capsys: pytest.CaptureFixture[str], fast_bag: Path, coeffs_yaml: Path
) -> None:
    """Fit at 0.5 degC/min, judged at 1 degC/min: the Tdot terms apply beyond the range.

    A note says so; --clamp-tdot clamps, and the deprecated --extrapolate-tdot is a no-op.
    """
    argv = ['evaluate', str(fast_bag), '--coeffs', str(coeffs_yaml)]
    assert cli.main(argv) == 0
    default = capsys.readouterr().out
    assert 'linear Tdot terms were applied beyond it' in default
    assert 'clamped' not in default
    assert cli.main([*argv, '--clamp-tdot']) == 0
    clamped = capsys.readouterr().out
    assert 'Tdot was clamped' in clamped
    after = {k: v[1] for k, v in parse_table(default).items()}
    after_clamped = {k: v[1] for k, v in parse_table(clamped).items()}
    # extrapolating removes more of the 1 degC/min drift than clamping at 0.5 degC/min
    assert all(after[k] < after_clamped[k] for k in after if k[2] == 10.0)
    assert cli.main([*argv, '--extrapolate-tdot']) == 0
    out = capsys.readouterr()
    assert 'default' in out.err
    assert parse_table(out.out) == parse_table(default)


def test_evaluate_missing_bag(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], coeffs_yaml: Path
) -> None:
    missing = tmp_path / 'gone'
    assert cli.main(['evaluate', str(missing), '--coeffs', str(coeffs_yaml)]) == 1
    assert str(missing) in error_line(capsys)


# --------------------------------------------------------------------------------------------
# entry point
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    'argv',
    [['--help'], ['calibrate', '--help'], ['calibrate', 'x'], ['fleet', 'calibrate', '--help']],
)
def test_help_and_argument_errors_import_nothing_heavy(argv: list[str]) -> None:
    """--help and a bad argument never import numpy, scipy, rosbags, matplotlib or dask."""
    code = (
        'import sys\n'
        'from fog_temp_comp.tools import cli\n'
        'try:\n'
        f'    cli.main({argv!r})\n'
        'except SystemExit:\n'
        '    pass\n'
        "heavy = ('numpy', 'scipy', 'rosbags', 'matplotlib', 'pywt', 'yaml', 'dask')\n"
        "print('IMPORTED', sorted(m for m in heavy if m in sys.modules))\n"
    )
    proc = subprocess.run(
        [sys.executable, '-c', code], capture_output=True, text=True, timeout=60, check=False
    )
    assert 'IMPORTED []' in proc.stdout, proc.stdout + proc.stderr


def _imported(code: str) -> list[str]:
    """Run ``code`` in a fresh interpreter; the heavy optional modules it imported."""
    code += (
        "\nheavy = ('scipy.signal', 'scipy.optimize', 'scipy.ndimage', 'scipy.stats', 'pywt')"
        "\nprint('IMPORTED', sorted(m for m in heavy if m in sys.modules))\n"
    )
    proc = subprocess.run(
        [sys.executable, '-c', 'import sys\n' + code],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    line = next(x for x in proc.stdout.splitlines() if x.startswith('IMPORTED'))
    return list(ast.literal_eval(line.removeprefix('IMPORTED ')))


def test_the_compensator_and_the_node_do_not_import_scipy_signal() -> None:
    """Importing the core, the node and the commands, and a Kalman compensator, cost no scipy.

    scipy.signal alone takes about 1 s to import; the default estimator does not need it.
    """
    code = (
        'from fog_temp_comp.core.compensator import Compensator\n'
        'from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS\n'
        'from fog_temp_comp.core.coefficients import load\n'
        'import fog_temp_comp.ros.node, fog_temp_comp.tools.commands\n'
        f'coeffs = load({str(REPO / "config" / "example_coefficients.yaml")!r})\n'
        'c = Compensator(coeffs.model, coeffs.denoise)\n'
        'c.add_temperature(1.0, 20.0)\n'
        'c.correct_block([1.5, 2.0], [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])\n'
    )
    assert _imported(code) == ['pywt']  # settings validation asks PyWavelets (~0.05 s)


def test_compensate_with_the_kalman_estimator_does_not_import_scipy_signal(
    tmp_path: Path, cal_bag: Path
) -> None:
    """``compensate`` with the default estimator never imports scipy.signal (start-up)."""
    coeffs = REPO / 'config' / 'example_coefficients.yaml'
    code = (
        'from fog_temp_comp.tools import cli\n'
        f"assert cli.main(['compensate', {str(cal_bag)!r}, '--coeffs', {str(coeffs)!r},"
        f" '-o', {str(tmp_path / 'out')!r}]) == 0\n"
    )
    assert 'scipy.signal' not in _imported(code)


def test_calibrate_with_the_defaults_does_not_import_scipy_signal(
    tmp_path: Path, cal_bag: Path
) -> None:
    """The default calibration (Kalman, cross-validated model choice) needs no scipy.

    Its refinements of time constants run SciPy's bounded Brent search without importing
    scipy.optimize (``core.bounded_search``: 0.5 s of start-up).
    """
    code = (
        'from fog_temp_comp.tools import cli\n'
        f"assert cli.main(['calibrate', {str(cal_bag)!r}, '-o', {str(tmp_path / 'c.yaml')!r},"
        " '--quiet']) == 0\n"
        'import yaml\n'
        f"selection = yaml.safe_load(open({str(tmp_path / 'c.yaml')!r}))['provenance']"
        "['selection']\n"
        "assert 'lag_s' in selection['chosen'], 'no time constant was refined'\n"
    )
    imported = _imported(code)
    assert not [name for name in imported if name.split('.')[0] == 'scipy'], imported


@pytest.mark.parametrize(
    ('method', 'module'), [('iir', 'scipy.signal'), ('wavelet', 'pywt'), ('kalman', None)]
)
def test_an_estimator_imports_what_it_needs_when_built(method: str, module: str | None) -> None:
    """The lazy imports are there when an estimator needs them (and only then)."""
    code = (
        'import dataclasses\n'
        'from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS\n'
        'from fog_temp_comp.core.tdot import make_estimator\n'
        f'e = make_estimator(dataclasses.replace(RECOMMENDED_SETTINGS, method={method!r}))\n'
        'for k in range(100):\n'
        '    e.add(10.0 * k, 20.0 + 0.01 * k)\n'
    )
    imported = _imported(code)
    assert 'scipy.signal' not in imported or module == 'scipy.signal'
    if module is not None:
        assert module in imported


def test_boundary_modes_are_pywavelets_modes() -> None:
    """``BOUNDARY_MODES`` is spelt out (no pywt import at module level): it must stay true."""
    import pywt

    from fog_temp_comp.core.denoise import BOUNDARY_MODES

    assert tuple(pywt.Modes.modes) == BOUNDARY_MODES


def test_single_gyro_commands_and_the_node_never_import_dask(
    tmp_path: Path, cal_bag: Path
) -> None:
    """The calibrate and evaluate commands and the node never import dask or distributed."""
    coeffs = tmp_path / 'c.yaml'
    code = (
        'import sys\n'
        'from fog_temp_comp.tools import cli\n'
        'import fog_temp_comp.ros.node\n'
        f"assert cli.main(['calibrate', {str(cal_bag)!r}, '-o', {str(coeffs)!r}]) == 0\n"
        f"assert cli.main(['evaluate', {str(cal_bag)!r}, '--coeffs', {str(coeffs)!r}]) == 0\n"
        "print('IMPORTED', sorted(m for m in ('dask', 'distributed') if m in sys.modules))\n"
    )
    proc = subprocess.run(
        [sys.executable, '-c', code], capture_output=True, text=True, timeout=120, check=False
    )
    assert 'IMPORTED []' in proc.stdout, proc.stdout + proc.stderr


def test_python_dash_m_help() -> None:
    proc = subprocess.run(
        [sys.executable, '-m', 'fog_temp_comp', '--help'],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert 'calibrate' in proc.stdout
    assert 'compensate' in proc.stdout
    assert proc.stdout.startswith('usage: fog-temp-comp')


def test_calibrate_shows_progress_on_stderr(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], cal_bag: Path
) -> None:
    assert cli.main(['calibrate', str(cal_bag), '-o', str(tmp_path / 'c.yaml')]) == 0
    last = capsys.readouterr().err.strip().split('\r')[-1]
    assert last.startswith(f'reading {cal_bag.name}: ')
    assert last.endswith(' s of data')


def test_simulate_cli_power_on_heating(tmp_path: Path) -> None:
    """``--power-on-heating-degC``: the run starts at the air and its sensor warms by that much."""
    runs = {}
    for heating in (0.0, 3.0):
        out = tmp_path / f'sim{heating:g}'
        argv = ['simulate', str(out), '--runs', 'soak:20', '--imu-hz', '1', '--seed', '4']
        assert cli.main([*argv, '--power-on-heating-degC', str(heating)]) == 0
        manifest = yaml.safe_load((out / 'manifest.yaml').read_text())
        assert manifest['power_on_heating_degC'] == heating
        runs[heating] = read_record(out / manifest['runs'][0]['bag'])
    cold, warm = runs[0.0], runs[3.0]
    assert abs(warm.temperature_degC[0] - cold.temperature_degC[0]) < 0.2  # at the air
    # 2 h later, settled about 3 degC above the unpowered unit's sensor
    assert warm.temperature_degC[-60:].mean() - cold.temperature_degC[-60:].mean() > 2.7


def test_simulate_cli_turn_on_shift_and_rest_motion_phases(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / 'sim'
    argv = ['simulate', str(out), '--runs', 'soak:20', '--imu-hz', '2', '--seed', '4']
    argv += ['--turn-on-shift-deg-h', '3,-2,1.5', '--motion-period-s', '120']
    argv += ['--motion-fraction', '0.25', '--motion-rate-deg-s', '2']
    assert cli.main(argv) == 0
    manifest = yaml.safe_load((out / 'manifest.yaml').read_text())
    assert manifest['turn_on_shift_deg_h'] == {'x': 3.0, 'y': -2.0, 'z': 1.5}
    assert (manifest['motion_period_s'], manifest['motion_fraction']) == (120.0, 0.25)
    assert [r['name'] for r in manifest['runs']] == ['soak_20']
    record = read_record(out / manifest['runs'][0]['bag'])
    with np.load(out / manifest['runs'][0]['truth']) as npz:
        truth = {k: npz[k] for k in npz.files}
    assert_array_equal(truth['turn_on_shift_deg_h'], [3.0, -2.0, 1.5])
    rotation_deg_h = truth['true_rotation_rad_s'] * DEG_H_PER_RAD_S
    phase_s = np.mod(record.imu_stamps_s - record.imu_stamps_s[0], 120.0)
    moving = phase_s >= 90.0
    # the bag: the rotation during the last quarter of each period only ...
    assert not rotation_deg_h[~moving].any()
    assert np.abs(rotation_deg_h[moving]).max() > 0.9 * 2.0 * 3600.0
    raw_deg_h = record.rates_rad_s * DEG_H_PER_RAD_S
    assert np.all(raw_deg_h[moving].std(axis=0) > 50 * raw_deg_h[~moving].std(axis=0))
    # ... and the shift on top of drift and noise everywhere (the chamber calibration's blind spot)
    residual = raw_deg_h - truth['true_drift_deg_h'] - rotation_deg_h
    assert_allclose(residual.mean(axis=0), [3.0, -2.0, 1.5], atol=0.3)
    for bad in (['--turn-on-shift-deg-h', '1,2'], ['--runs', 'bake:20']):
        with pytest.raises(SystemExit):
            cli.main(['simulate', str(tmp_path / 'bad'), *bad])
        assert 'expected' in capsys.readouterr().err


def test_simulate_into_a_folder_adds_runs_to_its_manifest(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A second simulate into the folder: its manifest lists both; other settings are refused."""
    out = tmp_path / 'sim'
    argv = ['simulate', str(out), '--imu-hz', '1', '--seed', '4', '--runs']
    assert cli.main([*argv, 'soak:20']) == 0
    assert cli.main([*argv, 'soak:30']) == 0
    manifest = yaml.safe_load((out / 'manifest.yaml').read_text())
    assert [r['name'] for r in manifest['runs']] == ['soak_20', 'soak_30']
    first, second = (read_record(out / r['bag']) for r in manifest['runs'])
    noise = [np.diff(r.rates_rad_s[:, 0]) for r in (first, second)]
    assert not np.allclose(noise[0], noise[1])  # a seed of its own, not the first run's noise
    capsys.readouterr()
    assert (
        cli.main(['simulate', str(out), '--imu-hz', '2', '--seed', '4', '--runs', 'soak:10']) == 1
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f'ERROR: {out} holds a simulation with other settings (imu_hz): write these '
        'runs to another directory'
    ]
    assert sorted(p.name for p in out.iterdir() if 'soak_10' in p.name) == []
    assert yaml.safe_load((out / 'manifest.yaml').read_text()) == manifest


def test_evaluate_notes_never_say_zero_percent(coeffs_yaml: Path) -> None:
    """A guard that acted on a few samples of many is counted, not rounded to '0 %'."""
    coeffs = load(coeffs_yaml)
    few = CompensatorCounters(imu_corrected=10_000, imu_tdot_clamped=3, imu_tdot_extrapolated=60)
    notes = clamp_notes('run', CompensatorStatus(counters=few), coeffs)
    assert len(notes) == 2
    assert notes[0].endswith('for 3 (under 1 %) of the gyro samples')
    assert notes[1].endswith('for 1 % of the gyro samples')
    none = CompensatorStatus(counters=CompensatorCounters(imu_corrected=10_000))
    assert clamp_notes('run', none, coeffs) == []


@pytest.mark.parametrize('command', ['calibrate', 'evaluate'])
def test_a_reader_that_leaves_early_costs_nothing(tmp_path: Path, command: str) -> None:
    """``fog-temp-comp calibrate ... | head``: the reader gone, the coefficients still written.

    The pipe's reader closes before the command prints: the command finishes, exit 0, no
    ``Broken pipe`` error (it lost the fit before).
    """
    out = tmp_path / 'c.yaml'
    argv = ['calibrate', str(REPO / 'bags' / 'cycle_0p2'), '-o', str(out), '--quiet']
    if command == 'evaluate':
        assert cli.main(argv) == 0
        argv = ['evaluate', str(REPO / 'bags' / 'cycle_1'), '--coeffs', str(out)]
    proc = subprocess.Popen(
        [sys.executable, '-m', 'fog_temp_comp', *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()  # the reader leaves before the first line
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 0, err
    assert 'Broken pipe' not in err and 'BrokenPipeError' not in err, err
    assert yaml.safe_load(out.read_text())['schema_version'] == 1


def test_fleet_without_dask_is_one_error_line(tmp_path: Path) -> None:
    """A ROS install brings no Dask: ``fleet calibrate`` says so, and writes nothing."""
    manifest = tmp_path / 'fleet.yaml'
    manifest.write_text('units: []\n')
    code = (
        "import sys\nsys.modules['distributed'] = None  # import distributed: ImportError\n"
        'from fog_temp_comp.tools import cli\n'
        f"sys.exit(cli.main(['fleet', 'calibrate', {str(manifest)!r}, '-o', "
        f'{str(tmp_path / "out")!r}]))\n'
    )
    proc = subprocess.run(
        [sys.executable, '-c', code], capture_output=True, text=True, timeout=60, check=False
    )
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr.startswith('ERROR: fleet calibrate runs on Dask'), proc.stderr
    assert "pip install 'dask[distributed]'" in proc.stderr
    assert 'Traceback' not in proc.stderr and not (tmp_path / 'out').exists()
