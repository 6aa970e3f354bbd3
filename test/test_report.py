"""The calibration report: valid PNGs and an HTML page that links them and shows the numbers."""

from __future__ import annotations

import dataclasses
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

from fog_temp_comp.core.calibration import GridTable, calibrate, grid_table
from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.evaluate import Score, compensate_record, score_record
from fog_temp_comp.core.fitstats import AxisFitStats, fit_drift
from fog_temp_comp.core.model import DriftModel
from fog_temp_comp.tools.report import (
    ReportRun,
    allan_deviation,
    format_coefficient,
    format_se,
    write_report,
)
from fog_temp_comp.tools.simulate import simulate_run

from simdata import SHORT_CHAMBER

PNG_SIGNATURE = b'\x89PNG\r\n\x1a\n'


class PageParser(HTMLParser):
    """Collects image sources, link targets, the title and the text of a page."""

    def __init__(self) -> None:
        super().__init__()
        self.images: list[str] = []
        self.links: list[str] = []
        self.title = ''
        self.text: list[str] = []
        self._in_title = False
        self.open_tags: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        values = dict(attrs)
        if tag == 'img':
            self.images.append(str(values['src']))
            assert values.get('alt'), 'every image has alt text'
        elif tag == 'a' and values.get('href'):
            self.links.append(str(values['href']))
        if tag not in ('img', 'meta', 'br'):
            self.open_tags.append(tag)
        self._in_title = tag == 'title'

    def handle_endtag(self, tag: str) -> None:
        assert self.open_tags and self.open_tags[-1] == tag, f'unbalanced </{tag}>'
        self.open_tags.pop()
        self._in_title = False

    def handle_data(self, data: str) -> None:
        if self._in_title:
            self.title += data
        self.text.append(data)


@pytest.fixture(scope='module')
def report_inputs() -> dict[str, object]:
    """A small calibration (0.5 degC/min short cycle) evaluated on a 1 degC/min cycle."""
    train = simulate_run('cycle', 0.5, SHORT_CHAMBER, seed=31).as_record()
    test = simulate_run('cycle', 1.0, SHORT_CHAMBER, seed=32).as_record()
    settings = DenoiseSettings(method='iir')
    table = grid_table(train, settings)
    coeffs = calibrate([train], settings)
    fits = fit_drift(
        table.temperature_degC, table.tdot_degC_per_min, table.rate_deg_h, coeffs.model.terms
    )
    corrected = compensate_record(test, coeffs)
    run = ReportRun(
        'cycle_1', test.imu_stamps_s, test.rates_rad_s, corrected,
        test.temp_stamps_s, test.temperature_degC,
    )  # fmt: skip
    scores = score_record('cycle_1', test.imu_stamps_s, test.rates_rad_s, corrected)
    # the same run again under a bag path whose name collides, as a plain tuple
    twin = tuple(run._replace(name='bags/cycle 1'))
    return {'table': table, 'model': coeffs.model, 'fits': fits, 'runs': [run, twin],
            'scores': scores}  # fmt: skip


@pytest.fixture(scope='module')
def report_dir(report_inputs: dict[str, object], tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp('report') / 'nested' / 'dir'
    index = write_report(
        out,
        warnings=['ill-conditioned fit <test & check>'],
        context={'bags': 'cycle_0p5'},
        **report_inputs,  # type: ignore[arg-type]
    )
    assert index == out / 'index.html'
    return out


def test_report_writes_the_expected_pngs(report_dir: Path) -> None:
    names = sorted(p.name for p in report_dir.glob('*.png'))
    # run names become safe, unique file names: 'bags/cycle 1' -> 'cycle_1_2'
    assert names == [
        'allan_cycle_1.png',
        'allan_cycle_1_2.png',
        'drift_vs_temperature.png',
        'residual_histogram.png',
        'timeseries_cycle_1.png',
        'timeseries_cycle_1_2.png',
    ]
    for name in names:
        path = report_dir / name
        assert path.read_bytes()[:8] == PNG_SIGNATURE
        image = imread(path)
        assert image.ndim == 3 and image.shape[0] > 300 and image.shape[1] > 600
        assert np.ptp(image[..., :3]) > 0.5  # not blank


def test_html_parses_and_references_every_png(report_dir: Path) -> None:
    page = PageParser()
    page.feed((report_dir / 'index.html').read_text(encoding='utf-8'))
    page.close()
    assert page.open_tags == []
    assert page.title == 'FOG temperature-drift calibration'
    pngs = {p.name for p in report_dir.glob('*.png')}
    assert set(page.images) == pngs
    assert pngs <= set(page.links)
    for target in page.images + page.links:
        assert (report_dir / target).is_file()
    text = ' '.join(page.text)
    assert 'ill-conditioned fit <test & check>' in text  # escaped in the source, shown as is


def test_html_shows_the_fit_and_score_values(
    report_dir: Path, report_inputs: dict[str, object]
) -> None:
    page = (report_dir / 'index.html').read_text(encoding='utf-8')
    model = report_inputs['model']
    fits = report_inputs['fits']
    scores = report_inputs['scores']
    assert isinstance(model, DriftModel) and isinstance(fits, list) and isinstance(scores, list)
    for j, fit in enumerate(fits):
        assert isinstance(fit, AxisFitStats)
        for i in range(len(model.terms)):
            assert format_coefficient(float(model.coefficients[i, j])) in page
            assert format_se(float(fit.se_hac[i])) in page
            assert format_se(float(fit.se_classical[i])) in page
        assert f'{fit.r_squared:.4f}' in page
        assert f'{fit.residual_std:.4f}' in page
        assert f'{fit.condition_number:.1f}' in page
    for name in ('d0_deg_h', 'dt_deg_h_per_degC', 'dtdot_deg_h_per_degC_per_min'):
        assert name in page
    t_range = model.temperature_range_degC
    assert f'{t_range.low:.2f}' in page and f'{t_range.high:.2f}' in page
    for s in scores:
        assert isinstance(s, Score)
        assert f'{s.stability_before_deg_h:.4f}' in page
        assert f'{s.stability_after_deg_h:.4f}' in page
        assert f'{s.range_after_deg_h:.4f}' in page
    assert 'cycle_0p5' in page


def test_report_without_runs_has_only_the_fit_plots(
    report_inputs: dict[str, object], tmp_path: Path
) -> None:
    table = report_inputs['table']
    assert isinstance(table, GridTable)
    index = write_report(
        tmp_path,
        table=table,
        model=report_inputs['model'],  # type: ignore[arg-type]
        fits=report_inputs['fits'],  # type: ignore[arg-type]
        runs=[],
        scores=[],
    )
    assert sorted(p.name for p in tmp_path.glob('*.png')) == [
        'drift_vs_temperature.png',
        'residual_histogram.png',
    ]
    page = PageParser()
    page.feed(index.read_text(encoding='utf-8'))
    assert sorted(page.images) == ['drift_vs_temperature.png', 'residual_histogram.png']


def test_allan_deviation_of_white_noise_falls_as_one_over_root_tau() -> None:
    rng = np.random.default_rng(8)
    n, sigma = 20_000, 0.5  # deg/h per 1 s sample
    curve = allan_deviation(np.arange(n, dtype=np.float64), rng.normal(0.0, sigma, n))
    assert curve.taus_s[0] == pytest.approx(1.0)
    assert np.all(np.diff(curve.taus_s) > 0)
    short = curve.taus_s <= 256
    expected = sigma / np.sqrt(curve.taus_s[short])
    np.testing.assert_allclose(curve.adev_deg_h[short], expected, rtol=0.15)
    assert allan_deviation(np.arange(5.0), np.zeros(5)).taus_s.size == 0


def test_scores_leave_out_the_rows_the_compensator_dropped() -> None:
    """Gyro before the first temperature (or a message sent twice) is NaN: scored on the rest."""
    run = simulate_run('cycle', 1.0, SHORT_CHAMBER, seed=12)
    coeffs = calibrate([run.as_record()], DenoiseSettings())
    record = run.as_record()
    late = dataclasses.replace(record, temp_stamps_s=record.temp_stamps_s + 1.5)
    corrected = compensate_record(late, coeffs)
    dropped = ~np.all(np.isfinite(corrected), axis=1)
    assert dropped.sum() == 2  # the gyro at 0 and 1 s, before the temperature at 1.5 s
    scores = score_record('cycle_1', run.imu_stamps_s, run.rates_rad_s, corrected)
    kept = score_record(
        'cycle_1', run.imu_stamps_s[~dropped], run.rates_rad_s[~dropped], corrected[~dropped]
    )
    assert scores == kept
    assert all(np.isfinite([s.stability_after_deg_h, s.range_after_deg_h]).all() for s in scores)
