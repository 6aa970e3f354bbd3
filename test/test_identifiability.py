"""calibrate refuses (or drops) a term its bags do not excite; progress lines fit a log."""

from __future__ import annotations

import io
import os
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from fog_temp_comp.bag.stream import Progress
from fog_temp_comp.core.coefficients import load
from fog_temp_comp.core.identifiability import (
    MIN_TDOT_SPAN_DEGC_PER_MIN,
    record_span,
    unidentifiable_terms,
)
from fog_temp_comp.tools import cli

REPO = Path(__file__).resolve().parents[1]
SOAKS = [REPO / 'bags' / name for name in ('soak_m20', 'soak_10', 'soak_30')]


def sensor(rng: np.random.Generator, truth_degC: np.ndarray) -> np.ndarray:
    """A 1/16 degC sensor with 0.02 degC noise."""
    return np.round((truth_degC + 0.02 * rng.standard_normal(truth_degC.size)) * 16) / 16


def test_soak_has_no_tdot_span_despite_noise_and_quantization(rng: np.random.Generator) -> None:
    t = np.arange(0.0, 3600.0, 1.0)
    span = record_span('soak', t, sensor(rng, np.full(t.size, 10.03)))
    assert span.temperature_degC[1] - span.temperature_degC[0] <= 0.125
    low, high = span.tdot_degC_per_min
    assert high - low < 0.2 * MIN_TDOT_SPAN_DEGC_PER_MIN


def test_ramp_span_is_its_rate(rng: np.random.Generator) -> None:
    t = np.arange(0.0, 3 * 3600.0, 1.0)
    rate = np.where(t < 5400.0, 0.2, -0.2)  # degC/min up, then down
    truth = 20.0 + np.cumsum(rate) / 60.0
    span = record_span('ramp', t, sensor(rng, truth))
    assert span.tdot_degC_per_min == pytest.approx((-0.2, 0.2), abs=0.01)
    assert span.temperature_degC == pytest.approx((truth.min(), truth.max()), abs=0.3)


def test_short_record_gives_one_slope_and_nan_is_ignored() -> None:
    t = np.arange(0.0, 120.0, 1.0)
    y = 20.0 + 0.5 * t / 60.0
    y[10] = np.nan
    span = record_span('short', t, y)
    assert span.tdot_degC_per_min == pytest.approx((0.5, 0.5))


def test_soaks_together_span_t_but_not_tdot(rng: np.random.Generator) -> None:
    t = np.arange(0.0, 3600.0, 1.0)
    spans = [record_span(f'soak_{v}', t, sensor(rng, np.full(t.size, v))) for v in (-20, 10, 30)]
    problems = unidentifiable_terms(spans, ('const', 'T', 'Tdot', 'T2', 'Tdot_lag'))
    assert [p.term for p in problems] == ['Tdot', 'Tdot_lag']
    message = problems[0].message
    assert message.startswith('term Tdot is not identifiable: the 3 bag(s) together span Tdot')
    found = re.findall(r'soak_(-?\d+): T (-?[\d.]+)\.\.(-?[\d.]+) degC, Tdot ', message)
    assert [int(v) for v, _, _ in found] == [-20, 10, 30]
    for v, low, high in found:
        assert float(low) - 0.15 <= int(v) <= float(high) + 0.15
    # one soak: T is not excited either
    single = unidentifiable_terms(spans[1:2], ('const', 'T', 'Tdot'))
    assert [p.term for p in single] == ['T', 'Tdot']
    assert 'soaks do not' in message
    # a ramp added to the soaks excites everything
    ramp = record_span('ramp', t, 20.0 + 0.2 * t / 60.0)
    assert unidentifiable_terms([*spans, ramp], ('const', 'T', 'Tdot', 'T_Tdot')) == []
    # a ramp alone (10 min at 1 degC/min): T moves, but at one rate, which a T term absorbs
    short = np.arange(0.0, 600.0, 1.0)
    alone = unidentifiable_terms([record_span('ramp', short, 30.0 + short / 60.0)], ('T', 'Tdot'))
    assert [p.term for p in alone] == ['Tdot']
    assert 'at one steady rate (a single ramp)' in alone[0].message
    assert 'add a run whose rate varies' in alone[0].message


def test_three_soak_bags_are_refused_naming_the_term_and_each_bag(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / 'c.yaml'
    args = ['calibrate', *map(str, SOAKS), '-o', str(out), '--quiet']
    assert cli.main(args) == 1
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and 'Traceback' not in captured.err
    assert lines[0].startswith('ERROR: term Tdot is not identifiable: the 3 bag(s) together')
    for bag in SOAKS:
        assert re.search(rf'{bag.name}: T -?\d+\.\d\d\.\.-?\d+\.\d\d degC, Tdot ', lines[0])
    assert lines[0].endswith('(or --drop-unidentifiable to fit without it)')
    assert not out.exists()
    # the paper's terms, asked for explicitly: refused all the same
    assert cli.main([*args, '--terms', 'const,T,Tdot']) == 1
    assert 'term Tdot is not identifiable' in capsys.readouterr().err


def test_three_soak_bags_with_drop_fit_t_only_and_warn(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / 'c.yaml'
    args = ['calibrate', *map(str, SOAKS), '-o', str(out), '--quiet', '--drop-unidentifiable']
    assert cli.main(args) == 0
    captured = capsys.readouterr()
    assert 'WARNING' not in captured.out  # warnings go to stderr
    warnings = [line for line in captured.err.splitlines() if line.startswith('WARNING: term')]
    assert len(warnings) == 1
    assert warnings[0].startswith('WARNING: term Tdot dropped (--drop-unidentifiable): the 3 ')
    coeffs = load(out)
    assert coeffs.model.terms == ('const', 'T')
    assert 'terms:' in out.read_text() and yaml.safe_load(out.read_text())


def test_progress_is_redrawn_on_a_terminal() -> None:
    controller, terminal = os.openpty()
    try:
        with open(terminal, 'w', closefd=False) as stream:
            assert stream.isatty()
            progress = Progress('bag_a', stream=stream)
            progress.update(10, 2_000_000_000, 1_000_000_000)
            progress.close()
            written = ''
            for _ in range(100):  # bounded: read until the final newline
                written += os.read(controller, 4096).decode()
                if '\n' in written:
                    break
    finally:
        os.close(terminal)
        os.close(controller)
    assert written.count('\r') >= 2  # redrawn in place, then the final line
    assert written.rstrip('\r\n').endswith('reading bag_a: 10 messages, 1 s of data')


def test_progress_into_a_log_is_one_line_per_bag() -> None:
    log = io.StringIO()
    for name in ('bag_a', 'bag_b'):
        progress = Progress(name, stream=log)
        for k in range(1, 4):
            progress.update(5, k * 1_000_000_000, 1_000_000_000)
        progress._shown = 0.0  # as if 0.5 s had passed: still no redraw
        progress.update(5, 4_000_000_000)
        progress.close()
    assert '\r' not in log.getvalue()
    assert log.getvalue().splitlines() == [
        'reading bag_a: 20 messages, 3 s of data',
        'reading bag_b: 20 messages, 3 s of data',
    ]


def test_calibrate_over_two_bags_logs_one_progress_line_each(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bags = [REPO / 'bags' / 'soak_10', REPO / 'bags' / 'cycle_1']
    assert cli.main(['calibrate', *map(str, bags), '-o', str(tmp_path / 'c.yaml'),
                     '--terms', 'const,T,Tdot']) == 0  # fmt: skip
    err = capsys.readouterr().err
    assert '\r' not in err
    lines = err.splitlines()
    assert [line.split(':')[0] for line in lines] == ['reading soak_10', 'reading cycle_1']
