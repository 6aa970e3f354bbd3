"""``fog-temp-comp calibrate`` options, in-process through ``cli.main`` on bags in tmp_path."""

from __future__ import annotations

import dataclasses
import re
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import matplotlib.image
import numpy as np
import pytest
import yaml
from numpy.testing import assert_allclose, assert_array_equal
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from fog_temp_comp.bag.bagio import (
    IMU_TYPE,
    TEMPERATURE_TYPE,
    BagWriter,
    make_imu,
    make_temperature,
    s_to_stamp_ns_array,
    write_chamber_bag,
)
from fog_temp_comp.core.coefficients import load
from fog_temp_comp.core.denoise import RECOMMENDED_SETTINGS
from fog_temp_comp.core.earth import earth_rate_body_deg_h, earth_rate_body_rad_s
from fog_temp_comp.core.evaluate import TAUS_S
from fog_temp_comp.core.model import coefficient_key
from fog_temp_comp.core.model_choice import choose_and_calibrate
from fog_temp_comp.core.selection import default_candidates
from fog_temp_comp.core.units import AXES, DEG_H_PER_RAD_S
from fog_temp_comp.tools import cli
from fog_temp_comp.tools.report import format_coefficient, format_se
from fog_temp_comp.tools.simulate import (
    TRUE_COEFFICIENTS,
    SimulatedRun,
    SimulationConfig,
    simulate_run,
)

# 1 degC/min cycles between 15 and 25 degC with 5 min soaks at 1 Hz: 2100 s, ~210 grid rows a
# run, enough to identify const, T and Tdot and fast enough for the held-out selection
CYCLE = SimulationConfig(
    imu_hz=1.0,
    temp_hz=1.0,
    low_degC=15.0,
    high_degC=25.0,
    start_degC=20.0,
    cycle_soak_s=300.0,
    soak_duration_s=600.0,
)
LATITUDE_DEG = 34.3
D0_KEY = coefficient_key('const')
TDOT_KEY = coefficient_key('Tdot')
T2_KEY = coefficient_key('T2')
PNG_SIGNATURE = b'\x89PNG\r\n\x1a\n'
# the paper's whole-record wavelet Tdot has no causal lag; with short bags its level is capped
WAVELET_LEVEL = pytest.mark.filterwarnings('ignore:level .* is too high:UserWarning')


def write_run(path: Path, run: SimulatedRun, rates_rad_s: np.ndarray | None = None) -> Path:
    """Write ``run`` (optionally with other gyro rates) as an MCAP bag."""
    write_chamber_bag(
        path,
        'mcap',
        imu_stamps_s=run.imu_stamps_s,
        rates_rad_s=run.rates_rad_s if rates_rad_s is None else rates_rad_s,
        temp_stamps_s=run.temp_stamps_s,
        temperature_degC=run.temperature_degC,
    )
    return path


def write_skewed_imu_stamps(path: Path, run: SimulatedRun, skew_s: float) -> Path:
    """A chamber bag whose Imu header stamps run ``skew_s`` ahead of their receive times.

    Receive (log) times and the temperature messages are those :func:`write_chamber_bag`
    writes, in the same order (temperature first on equal times).
    """
    imu_ns = s_to_stamp_ns_array(run.imu_stamps_s).tolist()
    temp_ns = s_to_stamp_ns_array(run.temp_stamps_s).tolist()
    skew_ns = round(skew_s * 1e9)
    events = [(ns, 0, k) for k, ns in enumerate(temp_ns)] + [
        (ns, 1, k) for k, ns in enumerate(imu_ns)
    ]
    events.sort()
    with BagWriter(path, 'mcap') as writer:
        writer.add_topic('/imu/temperature', TEMPERATURE_TYPE)
        writer.add_topic('/imu/data_raw', IMU_TYPE)
        for ns, kind, k in events:
            if kind == 0:
                msg = make_temperature(ns, 'imu_link', run.temperature_degC[k])
                writer.write('/imu/temperature', ns, msg)
            else:
                msg = make_imu(ns + skew_ns, 'imu_link', run.rates_rad_s[k])
                writer.write('/imu/data_raw', ns, msg)
    return path


def calibrate(bags: list[Path], out: Path, *extra: str) -> int:
    """``fog-temp-comp calibrate BAG... -o OUT --quiet EXTRA...``."""
    return cli.main(['calibrate', *map(str, bags), '-o', str(out), '--quiet', *extra])


def error_line(capsys: pytest.CaptureFixture[str]) -> str:
    """The single ``ERROR:`` line a failing command prints on stderr."""
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith('ERROR: ')
    return lines[0]


def read_yaml(path: Path) -> dict[str, Any]:
    """The coefficients file as plain data."""
    data = yaml.safe_load(path.read_text(encoding='utf-8'))
    assert isinstance(data, dict)
    return data


def coefficient_tolerance(fit: dict[str, Any], axis: str, key: str) -> float:
    """Allowed |fitted - true| for one coefficient.

    6 Newey-West standard errors (the residuals hold a 600 s Gauss-Markov bias; the HAC errors
    account for its correlation but are themselves estimated from ~200 rows) plus 0.01 deg/h
    for what the Tdot estimate leaves systematic.
    """
    return 6.0 * fit[axis]['standard_errors'][key] + 0.01


def validation_rows(stdout: str) -> dict[tuple[str, str, float], list[float]]:
    """Rows of the held-out validation table keyed by (run, axis, tau): its six numbers."""
    lines = stdout.splitlines()
    start = lines.index('held-out validation:') + 1
    assert lines[start].split()[:3] == ['run', 'axis', 'tau_s']
    assert set(lines[start + 1]) == {'-'}
    end = next(k for k in range(start, len(lines)) if lines[k].startswith('(deg/h'))
    assert all(line.startswith(('note: ', 'wrote ')) for line in lines[end + 1 :])
    rows = {}
    for line in lines[start + 2 : end]:
        run, axis, tau, *values = line.split()
        assert len(values) == 6
        rows[run, axis, float(tau)] = [float(v) for v in values]
    assert len(rows) == end - start - 2
    return rows


def stability_deg_h(stamps_s: np.ndarray, rates_rad_s: np.ndarray, tau_s: float) -> np.ndarray:
    """Std (ddof 1) of consecutive tau-s means of a gapless record whose length is a multiple."""
    per_window = round(tau_s / float(np.median(np.diff(stamps_s))))
    assert rates_rad_s.shape[0] % per_window == 0
    means = (rates_rad_s * DEG_H_PER_RAD_S).reshape(-1, per_window, 3).mean(axis=1)
    return means.std(axis=0, ddof=1)


class Page(HTMLParser):
    """Strict-enough HTML reader: checks that elements nest, collects images and table rows."""

    VOID = frozenset({'area', 'base', 'br', 'col', 'embed', 'hr', 'img', 'input', 'link', 'meta'})

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.open: list[str] = []
        self.images: list[str] = []
        self.rows: list[list[str]] = []
        self.text: list[str] = []
        self._cell: list[str] | None = None

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        if tag == 'img':
            self.images.append(dict(attrs)['src'] or '')
        if tag == 'br' and self._cell is not None:
            self._cell.append(' ')
        if tag in self.VOID:
            return
        self.open.append(tag)
        if tag == 'tr':
            self.rows.append([])
        elif tag in ('td', 'th'):
            self._cell = []

    def handle_endtag(self, tag: str) -> None:
        assert self.open and self.open[-1] == tag, (self.open, tag)
        self.open.pop()
        if tag in ('td', 'th') and self._cell is not None:
            self.rows[-1].append(' '.join(''.join(self._cell).split()))
            self._cell = None

    def handle_data(self, data: str) -> None:
        self.text.append(data)
        if self._cell is not None:
            self._cell.append(data)


def parse_page(index: Path) -> Page:
    """Parse ``index.html``; every element must be closed."""
    page = Page()
    page.feed(index.read_text(encoding='utf-8'))
    page.close()
    assert page.open == []
    return page


def check_images(page: Page, directory: Path) -> None:
    """Every ``<img src>`` of the page is a readable PNG file in ``directory``."""
    assert page.images
    for src in page.images:
        path = directory / src
        assert path.is_file(), src
        assert path.read_bytes()[:8] == PNG_SIGNATURE, src
        pixels = matplotlib.image.imread(path)
        assert pixels.ndim == 3
        assert min(pixels.shape[:2]) > 100, (src, pixels.shape)
        assert np.ptp(pixels) > 0, src  # not a blank image


def fit_row(page: Page, axis: str) -> list[str]:
    """The fit table's row of one axis (the first row starting with the axis name)."""
    return next(row for row in page.rows if row and row[0] == axis)


# --------------------------------------------------------------------------------------------
# Shared runs and bags
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope='module')
def data_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp('calibrate_cli')


@pytest.fixture(scope='module')
def train_run() -> SimulatedRun:
    return simulate_run('cycle', 1.0, CYCLE, seed=41)


@pytest.fixture(scope='module')
def train_bag(data_dir: Path, train_run: SimulatedRun) -> Path:
    return write_run(data_dir / 'train', train_run)


@pytest.fixture(scope='module')
def other_runs() -> list[SimulatedRun]:
    return [simulate_run('cycle', 1.0, CYCLE, seed=seed) for seed in (42, 43)]


@pytest.fixture(scope='module')
def other_bags(data_dir: Path, other_runs: list[SimulatedRun]) -> list[Path]:
    return [write_run(data_dir / f'other_{k}', run) for k, run in enumerate(other_runs)]


@pytest.fixture(scope='module')
def default_yaml(data_dir: Path, train_bag: Path) -> Path:
    """The calibration with every option at its default."""
    out = data_dir / 'default.yaml'
    assert calibrate([train_bag], out) == 0
    return out


# --------------------------------------------------------------------------------------------
# Earth rate
# --------------------------------------------------------------------------------------------


@WAVELET_LEVEL
def test_earth_rate_is_removed_before_the_fit(tmp_path: Path, train_run: SimulatedRun) -> None:
    earth_rad_s = earth_rate_body_rad_s(LATITUDE_DEG, 'enu')
    earth_deg_h = earth_rate_body_deg_h(LATITUDE_DEG, 'enu')
    assert np.linalg.norm(earth_deg_h) > 10.0  # the check below is not vacuous
    bag = write_run(tmp_path / 'earth', train_run, train_run.rates_rad_s + earth_rad_s)
    # the whole-record wavelet Tdot: the causal default estimator lags on these short ramps,
    # which biases T and, extrapolated 20 degC to T = 0, D0 by a few standard errors
    removed, kept = tmp_path / 'removed.yaml', tmp_path / 'kept.yaml'
    flags = ['--latitude-deg', str(LATITUDE_DEG), '--axes-orientation', 'enu']
    assert calibrate([bag], removed, '--denoise', 'wavelet', *flags) == 0
    assert calibrate([bag], kept, '--denoise', 'wavelet') == 0
    with_removal, without = load(removed), load(kept)

    d0 = with_removal.model.coefficient('const')
    d0_kept = without.model.coefficient('const')
    for j, axis in enumerate(AXES):
        tol = coefficient_tolerance(with_removal.fit, axis, D0_KEY)
        assert abs(d0[j] - TRUE_COEFFICIENTS[0, j]) <= tol, axis
        # without the removal, D0 also holds the Earth-rate projection
        assert abs((d0_kept[j] - d0[j]) - earth_deg_h[j]) <= tol, axis
    # least squares is linear in the gyro rate and a constant only moves the intercept, so
    # the shift is the projection to rounding (1e-6 deg/h) and the other terms do not move
    assert_allclose(d0_kept - d0, earth_deg_h, rtol=0.0, atol=1e-6)
    for term in ('T', 'Tdot'):
        assert_allclose(
            without.model.coefficient(term), with_removal.model.coefficient(term), rtol=1e-9
        )

    earth = with_removal.provenance['earth_rate']
    assert earth['latitude_deg'] == LATITUDE_DEG
    assert earth['axes_orientation'] == 'enu'
    assert_allclose(earth['removed_deg_h'], earth_deg_h, rtol=1e-12)
    assert 'earth_rate' not in without.provenance


@pytest.mark.parametrize(
    ('extra', 'named'),
    [
        (['--latitude-deg', '34.3'], '--axes-orientation'),
        (['--axes-orientation', 'enu'], '--latitude-deg'),
        (['--latitude-deg', '34.3', '--axes-orientation', 'xyz'], 'xyz'),
        (['--latitude-deg', '34.3', '--axes-orientation', 'een'], 'een'),
        (['--latitude-deg', '34.3', '--axes-orientation', '1,0,0'], '1,0,0'),
        (['--latitude-deg', '95', '--axes-orientation', 'enu'], 'latitude'),
    ],
)
def test_earth_rate_option_errors(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    train_bag: Path,
    extra: list[str],
    named: str,
) -> None:
    out = tmp_path / 'coeffs.yaml'
    assert calibrate([train_bag], out, *extra) == 1
    assert named in error_line(capsys)
    assert not out.exists()


# --------------------------------------------------------------------------------------------
# Model terms
# --------------------------------------------------------------------------------------------


def test_no_constant(tmp_path: Path, train_bag: Path, default_yaml: Path) -> None:
    out = tmp_path / 'no_d0.yaml'
    assert calibrate([train_bag], out, '--no-constant') == 0
    data = read_yaml(out)
    assert 'const' not in data['terms']
    assert data['terms'] == [t for t in read_yaml(default_yaml)['terms'] if t != 'const']
    assert D0_KEY not in data['model']
    for axis in AXES:
        assert D0_KEY not in data['axes'][axis], axis
    # the constant is dropped after the fit: the other coefficients are those of the full fit
    reduced, full = load(out).model, load(default_yaml).model
    for term in reduced.terms:
        assert_array_equal(reduced.coefficient(term), full.coefficient(term))
    # a model without D0 predicts the full model's drift minus D0
    temp = np.array([18.0, 20.0, 22.0])
    tdot = np.array([-0.3, 0.0, 0.4])
    assert_allclose(
        reduced.drift_deg_h(temp, tdot),
        full.drift_deg_h(temp, tdot) - full.coefficient('const'),
        rtol=1e-12,
        atol=1e-12,
    )


def test_terms_with_t2(tmp_path: Path, train_bag: Path) -> None:
    out = tmp_path / 't2.yaml'
    assert calibrate([train_bag], out, '--terms', 'const,T,Tdot,T2') == 0
    data = read_yaml(out)
    assert data['terms'] == ['const', 'T', 'Tdot', 'T2']
    for axis in AXES:
        assert T2_KEY in data['axes'][axis], axis
        assert T2_KEY in data['fit'][axis]['standard_errors'], axis
    assert load(out).model.coefficient('T2').shape == (len(AXES),)


def test_unknown_term(tmp_path: Path, capsys: pytest.CaptureFixture[str], train_bag: Path) -> None:
    out = tmp_path / 'bad.yaml'
    assert calibrate([train_bag], out, '--terms', 'const,T,Tdott') == 1
    assert "'Tdott'" in error_line(capsys)
    assert not out.exists()


# --------------------------------------------------------------------------------------------
# Validation, report
# --------------------------------------------------------------------------------------------


def test_validate_prints_the_held_out_table(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    train_bag: Path,
    other_bags: list[Path],
    other_runs: list[SimulatedRun],
) -> None:
    out = tmp_path / 'coeffs.yaml'
    assert calibrate([train_bag], out, '--validate', *map(str, other_bags)) == 0
    rows = validation_rows(capsys.readouterr().out)
    assert set(rows) == {(b.name, a, tau) for b in other_bags for a in AXES for tau in TAUS_S}
    assert set(TAUS_S) == {10.0, 100.0}
    for bag, run in zip(other_bags, other_runs, strict=True):
        before = stability_deg_h(run.imu_stamps_s, run.rates_rad_s, 10.0)
        for j, axis in enumerate(AXES):
            stab_before, stab_after, *_ = rows[bag.name, axis, 10.0]
            assert stab_before == pytest.approx(before[j], abs=6e-5)  # printed to 4 decimals
            # a held-out cycle: compensation removes most of the drift
            assert stab_after < stab_before, (bag.name, axis)


def test_report(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], train_bag: Path, default_yaml: Path
) -> None:
    out, report = tmp_path / 'coeffs.yaml', tmp_path / 'report'
    assert calibrate([train_bag], out, '--report', str(report)) == 0
    index = report / 'index.html'
    assert f'report: {index}' in capsys.readouterr().out
    page = parse_page(index)
    check_images(page, report)
    coeffs = load(out)
    # the report belongs to the same fit as the YAML written beside it
    assert_array_equal(coeffs.model.coefficients, load(default_yaml).model.coefficients)
    column = 1 + coeffs.model.terms.index('Tdot')
    for j, axis in enumerate(AXES):
        cell = fit_row(page, axis)[column]
        value = format_coefficient(coeffs.model.coefficient('Tdot')[j])
        se = format_se(coeffs.fit[axis]['standard_errors'][TDOT_KEY])
        assert cell.startswith(f'{value} ± {se}'), (axis, cell)
    # without --validate the page shows the training run
    assert f'{train_bag.name} (training)' in ''.join(page.text)


def test_report_with_validation_runs(
    tmp_path: Path, train_bag: Path, other_bags: list[Path]
) -> None:
    out, report = tmp_path / 'coeffs.yaml', tmp_path / 'report'
    argv = ['--validate', *map(str, other_bags), '--report', str(report)]
    assert calibrate([train_bag], out, *argv) == 0
    page = parse_page(report / 'index.html')
    check_images(page, report)
    scored = {row[0] for row in page.rows if len(row) == 9 and row[1] in AXES}
    assert scored == {b.name for b in other_bags}
    for bag in other_bags:
        assert f'timeseries_{bag.name}.png' in page.images
    assert f'{train_bag.name} (training)' not in ''.join(page.text)


def test_report_standard_errors_without_constant(tmp_path: Path, train_bag: Path) -> None:
    # each coefficient of the fit table must carry its own standard error, also when
    # --no-constant drops D0 from the model written (the fit itself had the constant)
    out, report = tmp_path / 'coeffs.yaml', tmp_path / 'report'
    assert calibrate([train_bag], out, '--no-constant', '--report', str(report)) == 0
    coeffs = load(out)
    page = parse_page(report / 'index.html')
    for i, term in enumerate(coeffs.model.terms):
        for j, axis in enumerate(AXES):
            cell = fit_row(page, axis)[1 + i]
            value = format_coefficient(coeffs.model.coefficients[i, j])
            se = format_se(coeffs.fit[axis]['standard_errors'][coefficient_key(term)])
            assert cell.startswith(f'{value} ± {se}'), (term, axis, cell)


# --------------------------------------------------------------------------------------------
# Selection on held-out runs
# --------------------------------------------------------------------------------------------


def chosen_candidate(stdout: str) -> str:
    """Name of the candidate marked ``<- chosen`` in the selection table (exactly one)."""
    marked = [line for line in stdout.splitlines() if line.endswith(' <- chosen')]
    assert len(marked) == 1, stdout
    names = [c.name for c in default_candidates(RECOMMENDED_SETTINGS)]
    # the longest name the line starts with: 'paper' is a prefix of 'paper + fitted coil lag'
    return max((n for n in names if marked[0].startswith(n + ' ')), key=len)


def check_selection(out: Path, chosen: str, mode: str) -> None:
    """The YAML records the selection and holds the chosen candidate's model."""
    coeffs = load(out)
    selection = coeffs.provenance['selection']
    assert selection['chosen'] == chosen
    assert selection['mode'] == mode
    candidates = {c.name: c for c in default_candidates(RECOMMENDED_SETTINGS)}
    assert set(selection['candidates']) == set(candidates)
    assert coeffs.model.terms == candidates[chosen].terms


def test_heldout_selection(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    train_bag: Path,
    other_bags: list[Path],
) -> None:
    out = tmp_path / 'coeffs.yaml'
    # a given estimator (--denoise) selects among the fixed candidates on the held-out run
    assert calibrate([train_bag], out, '--heldout', str(other_bags[0]), '--denoise', 'kalman') == 0
    check_selection(out, chosen_candidate(capsys.readouterr().out), 'held-out runs')


def test_leave_one_run_out(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    train_bag: Path,
    other_bags: list[Path],
) -> None:
    out = tmp_path / 'coeffs.yaml'
    bags = [train_bag, other_bags[0]]
    assert calibrate(bags, out, '--leave-one-run-out') == 0
    check_selection(out, chosen_candidate(capsys.readouterr().out), 'leave-one-run-out')
    assert load(out).provenance['bags'] == [str(b) for b in bags]


def test_leave_one_run_out_needs_two_bags(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], train_bag: Path
) -> None:
    out = tmp_path / 'coeffs.yaml'
    assert calibrate([train_bag], out, '--leave-one-run-out') == 1
    assert 'two' in error_line(capsys)
    assert not out.exists()


# --------------------------------------------------------------------------------------------
# Input options
# --------------------------------------------------------------------------------------------


def test_time_source_receive(tmp_path: Path, train_run: SimulatedRun, default_yaml: Path) -> None:
    # Imu header stamps 5 min ahead of the receive times (a gyro clock set wrong): aligned by
    # receive time the bag is the default bag, aligned by header it is not
    bag = write_skewed_imu_stamps(tmp_path / 'skewed', train_run, 300.0)
    receive, header = tmp_path / 'receive.yaml', tmp_path / 'header.yaml'
    assert calibrate([bag], receive, '--time-source', 'receive') == 0
    assert calibrate([bag], header) == 0
    expected = load(default_yaml).model
    assert load(receive).model.terms == expected.terms
    assert_array_equal(load(receive).model.coefficients, expected.coefficients)
    skewed = load(header).model
    assert skewed.terms != expected.terms or not np.allclose(
        skewed.coefficients, expected.coefficients, rtol=0.01, atol=0.0
    )


def test_temp_field_on_a_standard_bag(tmp_path: Path, train_bag: Path, default_yaml: Path) -> None:
    out = tmp_path / 'field.yaml'
    extra = ['--temp-topic', '/imu/temperature', '--temp-field', 'temperature']
    assert calibrate([train_bag], out, *extra) == 0
    # the generic per-message path reads the very same stamps and values as the batch decoder
    assert_array_equal(load(out).model.coefficients, load(default_yaml).model.coefficients)
    assert load(out).provenance['temperature_topics'] == ['/imu/temperature']


# --------------------------------------------------------------------------------------------
# Progress, fit statistics, output errors
# --------------------------------------------------------------------------------------------


def test_progress_line(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    train_bag: Path,
    train_run: SimulatedRun,
) -> None:
    assert cli.main(['calibrate', str(train_bag), '-o', str(tmp_path / 'c.yaml')]) == 0
    err = capsys.readouterr().err
    assert err.endswith('\n')
    last = re.split('[\r\n]', err.rstrip('\n'))[-1]
    match = re.fullmatch(r'reading (\S+): ([\d,]+) messages, ([\d,]+) s of data', last)
    assert match, last
    with AnyReader([train_bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        counts = {info.msgtype: info.msgcount for info in reader.topics.values()}
    # log time = header stamp in these bags: the data span from the first to the last message
    stamps = np.r_[train_run.imu_stamps_s, train_run.temp_stamps_s]
    span_s = float(stamps.max() - stamps.min())
    assert match[1] == train_bag.name
    assert int(match[2].replace(',', '')) == counts[IMU_TYPE] + counts[TEMPERATURE_TYPE]
    assert match[3] == f'{span_s:,.0f}'


def test_fit_statistics_in_yaml_and_stdout(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], train_bag: Path
) -> None:
    out = tmp_path / 'coeffs.yaml'
    assert calibrate([train_bag], out) == 0
    stdout = capsys.readouterr().out
    data = read_yaml(out)
    keys = [coefficient_key(t) for t in data['terms']]
    for axis in AXES:
        fit = data['fit'][axis]
        assert fit['standard_error_method'].startswith('newey-west')
        for block in ('standard_errors', 'standard_errors_classical'):
            assert list(fit[block]) == keys, (axis, block)
            assert all(np.isfinite(v) and v > 0 for v in fit[block].values()), (axis, block)
        # 2-norm condition number of the column-scaled design: at least 1
        assert np.isfinite(fit['condition_number'])
        assert fit['condition_number'] >= 1.0

    printed = [line.strip() for line in stdout.splitlines() if '+-' in line]
    assert [line.split(':')[0] for line in printed] == list(AXES)
    for line, axis in zip(printed, AXES, strict=True):
        fit = data['fit'][axis]
        pairs = dict(re.findall(r'(\w+)=([-+\d.e]+\+-[\d.e-]+)', line))
        assert list(pairs) == data['terms'], line
        for term, key in zip(data['terms'], keys, strict=True):
            value, se = (float(v) for v in pairs[term].split('+-'))
            # printed to 6 and 2 significant digits
            assert value == pytest.approx(data['axes'][axis][key], rel=1e-5), (axis, term)
            assert se == pytest.approx(fit['standard_errors'][key], rel=0.05), (axis, term)
        cond = float(re.search(r'cond=([\d.]+)', line)[1])  # type: ignore[index]
        assert cond == pytest.approx(fit['condition_number'], abs=0.05)


def test_output_in_a_missing_directory(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], train_bag: Path
) -> None:
    # an unwritable -o is a user error: one ERROR line and exit code 1, not a traceback
    out = tmp_path / 'no_such_dir' / 'coeffs.yaml'
    assert calibrate([train_bag], out) == 1
    assert str(out) in error_line(capsys)


def test_a_bump_in_the_training_bag_is_dropped_and_reported(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    train_run: SimulatedRun,
    train_bag: Path,
) -> None:
    """One sample of 3 deg/s (a touch of the turntable): warned, in the YAML, fit unharmed."""
    rates = train_run.rates_rad_s.copy()
    rates[1000] += np.deg2rad(3.0)
    bag = write_run(tmp_path / 'bumped', train_run, rates)
    out, reference = tmp_path / 'bumped.yaml', tmp_path / 'clean.yaml'
    assert calibrate([train_bag], reference, '--terms', 'const,T,Tdot') == 0
    capsys.readouterr()
    assert calibrate([bag], out, '--terms', 'const,T,Tdot') == 0
    warning = [line for line in capsys.readouterr().err.splitlines() if 'outliers' in line]
    assert len(warning) == 1 and warning[0].startswith('WARNING: ')
    assert '1 of ' in warning[0] and 'a bump, a rotation or a data error?' in warning[0]
    data = read_yaml(out)
    (entry,) = data['provenance']['gyro_outliers'].values()
    assert entry['bins_dropped'] == 1
    assert entry['worst_deviation_deg_h'] > 1000.0  # 3 deg/s over a 10 s bin of 1 Hz samples
    clean = read_yaml(reference)
    assert 'gyro_outliers' not in clean['provenance']
    for axis in AXES:
        errors = clean['fit'][axis]['standard_errors']
        for key, value in clean['axes'][axis].items():
            assert abs(data['axes'][axis][key] - value) < 0.5 * errors[key], (axis, key)


def test_the_default_calibration_of_a_bag_is_the_cores_of_its_run(
    train_run: SimulatedRun, default_yaml: Path
) -> None:
    """``calibrate BAG`` chooses and fits as the core does on the run in memory.

    The bag is read and its gyro reduced to grid means on the way: what
    ``benchmarks/accuracy.py`` measures (on runs in memory) is what a user's command gets.
    """
    result, _, chosen = choose_and_calibrate([train_run.as_record()], RECOMMENDED_SETTINGS)
    from_bag = load(default_yaml)
    assert from_bag.model.terms == chosen.structure.terms
    # the same settings; a refined time constant to rounding (the grid means' sums differ)
    for name, value in dataclasses.asdict(result.coefficients.denoise).items():
        expected = pytest.approx(value, rel=1e-9) if isinstance(value, float) else value
        assert getattr(from_bag.denoise, name) == expected, name
    assert_allclose(
        from_bag.model.coefficients, result.coefficients.model.coefficients, rtol=1e-9, atol=1e-12
    )
