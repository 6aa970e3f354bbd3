"""Data no command can use, or only in part, through the real CLI: evaluate and compensate too.

NaN or inf throughout a stream is an ``ERROR:`` (nothing to fit, score or correct with), a
non-finite gyro message in compensate a ``WARNING:`` (written as the node writes it), an absurd
gyro rate is dropped as NaN is (no numpy RuntimeWarning: pytest makes those errors), a pause in
both streams far longer than their sampling splits a calibration run, and a run shorter than
the averaging time says so in evaluate's table.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from test_bad_input import SMALL, write_as_received

from fog_temp_comp.bag.bagio import write_chamber_bag
from fog_temp_comp.bag.stream import read_record
from fog_temp_comp.core.evaluate import Score, format_scores
from fog_temp_comp.tools import cli
from fog_temp_comp.tools.simulate import simulate_run

Arrays = dict[str, np.ndarray]


@pytest.fixture(scope='module')
def base(tmp_path_factory: pytest.TempPathFactory) -> tuple[Arrays, Path]:
    """A small chamber run's arrays, and coefficients fitted on it."""
    run = simulate_run('cycle', 2.0, SMALL, seed=5)
    arrays = {
        'imu_stamps_s': run.imu_stamps_s,
        'rates_rad_s': run.rates_rad_s,
        'temp_stamps_s': run.temp_stamps_s,
        'temperature_degC': run.temperature_degC,
    }
    root = tmp_path_factory.mktemp('base')
    write_chamber_bag(root / 'run', 'mcap', **arrays)
    coeffs = root / 'c.yaml'
    argv = ['calibrate', str(root / 'run'), '-o', str(coeffs), '--terms', 'const,T', '--quiet']
    assert cli.main(argv) == 0
    return arrays, coeffs


def bag(tmp_path: Path, arrays: Arrays, **changes: np.ndarray) -> Path:
    path = tmp_path / 'bad'
    write_chamber_bag(path, 'mcap', **{**{k: v.copy() for k, v in arrays.items()}, **changes})
    return path


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = cli.main(argv)
    out, err = capsys.readouterr()
    assert 'Traceback' not in err and 'RuntimeWarning' not in err, err
    return code, out, err


def test_temperature_nan_throughout_is_an_error_for_evaluate_and_compensate(
    base: tuple[Arrays, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    arrays, coeffs = base
    path = bag(tmp_path, arrays, temperature_degC=np.full(arrays['temp_stamps_s'].size, np.nan))
    expected = 'no finite temperature reading on /imu/temperature'
    code, _, err = run_cli(['evaluate', str(path), '--coeffs', str(coeffs)], capsys)
    assert code == 1 and err.startswith('ERROR: ') and expected in err, err
    out = tmp_path / 'out'
    code, _, err = run_cli(
        ['compensate', str(path), '--coeffs', str(coeffs), '-o', str(out)], capsys
    )
    assert code == 1 and not out.exists(), err
    (line,) = [x for x in err.splitlines() if x.startswith('ERROR: ')]
    assert expected in line and 'no gyro message could be corrected' in line


def test_gyro_nan_throughout_evaluate_refuses_compensate_warns_as_the_node_counts(
    base: tuple[Arrays, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    arrays, coeffs = base
    n = arrays['imu_stamps_s'].size
    path = bag(tmp_path, arrays, rates_rad_s=np.full((n, 3), np.nan))
    code, _, err = run_cli(['evaluate', str(path), '--coeffs', str(coeffs)], capsys)
    assert code == 1 and err.startswith('ERROR: ') and 'no finite gyro rate' in err, err
    out = tmp_path / 'out'
    code, _, err = run_cli(
        ['compensate', str(path), '--coeffs', str(coeffs), '-o', str(out)], capsys
    )
    assert code == 0, err
    (line,) = [x for x in err.splitlines() if x.startswith('WARNING: ')]
    assert f'{n} of {n} gyro messages with a rate that is not finite' in line
    assert np.isnan(read_record(out, gyro_topic='/imu/data').rates_rad_s).all()


def test_an_absurd_or_infinite_gyro_rate_is_dropped_by_evaluate_with_a_warning(
    base: tuple[Arrays, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """1e308 once, or +inf on axis x throughout: the table stays finite where it can."""
    arrays, coeffs = base
    rates = arrays['rates_rad_s'].copy()
    rates[100, 0] = 1e308
    path = bag(tmp_path, arrays, rates_rad_s=rates)
    code, out, err = run_cli(['evaluate', str(path), '--coeffs', str(coeffs)], capsys)
    assert code == 0 and 'WARNING: ' in err and 'dropped 1 of' in err, err
    assert 'nan' not in out and 'inf' not in out.replace('info', ''), out
    rates = arrays['rates_rad_s'].copy()
    rates[:, 0] = np.inf
    path = bag(tmp_path / 'x', arrays, rates_rad_s=rates)
    code, out, err = run_cli(['evaluate', str(path), '--coeffs', str(coeffs)], capsys)
    assert code == 0 and 'no finite gyro rate on axis x' in err and 'not scored' in err, err
    rows = [line.split() for line in out.splitlines() if line.startswith('bad ')]
    assert {r[1] for r in rows if r[3] == 'nan'} == {'x'}, out


def test_a_clock_jump_in_both_streams_splits_the_calibration_run(
    base: tuple[Arrays, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Stamps 1e8 s later from the middle on: two pieces, the fit as without the jump."""
    arrays, _ = base
    middle = arrays['imu_stamps_s'][arrays['imu_stamps_s'].size // 2]
    changes = {
        k: np.where(arrays[k] > middle, arrays[k] + 1e8, arrays[k])
        for k in ('imu_stamps_s', 'temp_stamps_s')
    }
    fits = {}
    for name, bag_path in (
        ('jump', bag(tmp_path, arrays, **changes)),
        ('clean', bag(tmp_path / 'c', arrays)),
    ):
        output = tmp_path / f'{name}.yaml'
        argv = ['calibrate', str(bag_path), '-o', str(output), '--terms', 'const,T', '--quiet']
        code, _, err = run_cli(argv, capsys)
        assert code == 0, err
        fits[name] = yaml.safe_load(output.read_text())
        if name == 'jump':
            (line,) = [x for x in err.splitlines() if 'split there' in x]
            assert line.startswith('WARNING: ') and '1 pause(s) of up to 1e+08 s' in line
            split = fits[name]['provenance']['split_at_pauses'][str(bag_path)]
            assert split['gyro_dropped'] == split['temperature_dropped'] == 0
    for axis in ('x', 'y', 'z'):
        jump, clean = fits['jump']['axes'][axis], fits['clean']['axes'][axis]
        assert jump['dt_deg_h_per_degC'] == pytest.approx(clean['dt_deg_h_per_degC'], abs=0.02)
    noise = [fits[k]['denoise']['temperature_noise_degC'] for k in ('jump', 'clean')]
    assert noise[0] == pytest.approx(noise[1], rel=0.2)


def test_evaluate_says_a_run_shorter_than_two_windows_is_why_it_scores_nan(
    base: tuple[Arrays, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    arrays, coeffs = base
    short = {}
    for stamps, values in (('imu_stamps_s', 'rates_rad_s'), ('temp_stamps_s', 'temperature_degC')):
        keep = arrays[stamps] < arrays[stamps][0] + 15.0
        short[stamps], short[values] = arrays[stamps][keep], arrays[values][keep]
    path = bag(tmp_path, arrays, **short)
    code, out, err = run_cli(['evaluate', str(path), '--coeffs', str(coeffs)], capsys)
    assert code == 0, err
    assert '(nan at tau 10, 100 s: the run is shorter than two windows of tau' in out, out
    assert 'never changes' not in out, out


def test_format_scores_tells_a_short_run_from_a_flat_or_nan_rate() -> None:
    nan = float('nan')
    flat = Score('a', 'x', 10.0, 0.0, 0.0, 0.0, 0.0, windows=5)
    short = Score('b', 'x', 100.0, nan, nan, nan, nan, windows=1)
    text = format_scores([flat, short])
    assert '(nan at tau 100 s: the run is shorter than two windows' in text
    assert 'never changes, or is NaN' in text
    assert 'shorter' not in format_scores([flat]) and 'never' not in format_scores(
        [Score('c', 'x', 10.0, 1.0, 0.5, 1.0, 0.5)]
    )


@pytest.mark.parametrize(
    ('stamps', 'what'),
    [
        ('imu_stamps_s', 'gyro message on /imu/data_raw'),
        ('temp_stamps_s', 'temperature reading on /imu/temperature'),
    ],
)
def test_a_stream_whose_stamps_are_all_the_same_is_refused_for_that_reason(
    stamps: str, what: str, base: tuple[Arrays, Path], tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:  # fmt: skip
    """Not "never changes on any axis" nor a numpy warning: the stamps are the cause."""
    arrays, coeffs = base
    path = tmp_path / 'bad'
    changed = {**arrays, stamps: np.full(arrays[stamps].size, arrays[stamps][0])}
    write_as_received(path, 'mcap', changed)  # log times as recorded, header stamps stuck
    expected = f'every {what} has the same header stamp'
    for argv in (
        ['calibrate', str(path), '-o', str(tmp_path / 'c.yaml'), '--quiet'],
        ['evaluate', str(path), '--coeffs', str(coeffs)],
    ):
        code, _, err = run_cli(argv, capsys)
        assert code == 1, err
        *warnings, last = err.strip().splitlines()
        assert last.startswith('ERROR: ') and expected in last, err
        assert all(w.startswith('WARNING: ') for w in warnings), err
        assert 'never changes' not in err
    assert not (tmp_path / 'c.yaml').exists()


def test_compensate_says_when_every_temperature_reading_has_the_same_stamp(
    base: tuple[Arrays, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The node drops them as repeated stamps and holds the correction: compensate says both."""
    arrays, coeffs = base
    stamps = np.full(arrays['temp_stamps_s'].size, arrays['temp_stamps_s'][0])
    path = bag(tmp_path, arrays, temp_stamps_s=stamps)
    out = tmp_path / 'out'
    code, _, err = run_cli(
        ['compensate', str(path), '--coeffs', str(coeffs), '-o', str(out)], capsys
    )
    assert code == 0, err
    n = stamps.size
    assert f'{n - 1} of {n} temperature readings dropped for their stamps' in err
    assert 'got the last correction held while the temperature was stale' in err
    code, _, err = run_cli(  # the clean run: neither line
        ['compensate', str(bag(tmp_path / 'clean', arrays)), '--coeffs', str(coeffs), '-o',
         str(tmp_path / 'out2')], capsys
    )  # fmt: skip
    assert code == 0 and 'WARNING' not in err, err


def test_held_out_bags_get_the_checks_of_training_ones(
    base: tuple[Arrays, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """NaN readings dropped with a warning (scored, the sensor still warms up), or refused.

    With every 7th temperature NaN in the held-out bag, the quantized filter scored 1.01
    (no correction: its warm-up never ended on the readings left) and was not used.
    """
    arrays, _ = base
    train = bag(tmp_path / 'train', arrays)
    temps = arrays['temperature_degC'].copy()
    temps[::7] = np.nan
    heldout = bag(tmp_path / 'held', arrays, temperature_degC=temps)
    output = tmp_path / 'c.yaml'
    argv = ['calibrate', str(train), '--heldout', str(heldout), '-o', str(output), '--quiet']
    code, _, err = run_cli(argv, capsys)
    assert code == 0, err
    (line,) = [x for x in err.splitlines() if 'not finite' in x]
    assert line.startswith(f'WARNING: {heldout}: dropped 0 of') and 'temperature readings' in line
    selection = yaml.safe_load(output.read_text())['provenance']['selection']
    quantized = selection['quantized_likelihood']
    assert quantized['used'] and quantized['criterion'] < 1.05 * quantized['criterion_gaussian']
    temps[:] = np.nan
    heldout = bag(tmp_path / 'nan', arrays, temperature_degC=temps)
    argv = ['calibrate', str(train), '--heldout', str(heldout), '-o', str(tmp_path / 'n.yaml')]
    code, _, err = run_cli(argv, capsys)
    assert code == 1 and not (tmp_path / 'n.yaml').exists()
    (line,) = [x for x in err.splitlines() if x.startswith('ERROR: ')]
    assert line.startswith(f'ERROR: {heldout}: no finite temperature reading'), err


def test_evaluate_scores_a_run_with_a_clock_jump_as_the_run_without_it(
    base: tuple[Arrays, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Stamps 1e8 s later from the middle on: the replay restarts there as the node would.

    No split is needed: the 10 s rows are the clean run's within 1 %, not a 1e8 s run.
    """
    arrays, coeffs = base
    middle = arrays['imu_stamps_s'][arrays['imu_stamps_s'].size // 2]
    changes = {
        k: np.where(arrays[k] > middle, arrays[k] + 1e8, arrays[k])
        for k in ('imu_stamps_s', 'temp_stamps_s')
    }
    rows = {}
    for name, bag_path in (
        ('jump', bag(tmp_path, arrays, **changes)),
        ('clean', bag(tmp_path / 'c', arrays)),
    ):
        code, out, err = run_cli(['evaluate', str(bag_path), '--coeffs', str(coeffs)], capsys)
        assert code == 0, err
        rows[name] = np.array(
            [[float(v) for v in line.split()[3:]] for line in out.splitlines()
             if line.startswith('bad ') and line.split()[2] == '10']
        )  # fmt: skip
    assert rows['jump'].shape == rows['clean'].shape == (3, 6)
    values = [0, 1, 3, 4]  # stability and range before and after (the ratios are rounded)
    np.testing.assert_allclose(rows['jump'][:, values], rows['clean'][:, values], rtol=0.01)
