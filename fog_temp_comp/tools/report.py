"""Calibration report: PNG plots and a small self-contained HTML page that links them.

``write_report`` renders, with matplotlib's Agg backend (no display needed):

- ``drift_vs_temperature.png``: the 10 s grid means against temperature, coloured by Tdot, with
  the fitted model at the same (T, Tdot) and its Tdot = 0 line;
- ``residual_histogram.png``: the fit residuals per axis with the normal density of the same std;
- ``timeseries_<run>.png``: per run, 10 s means before and after compensation (deg/h, each with
  its mean removed) and the temperature on a second axis;
- ``allan_<run>.png``: per run, the overlapping Allan deviation (IEEE Std 952 / NIST SP 1065)
  before and after compensation, computed by ``allantools.oadev``;
- ``index.html``: the fit table (coefficients +- standard errors, R^2, residual std, condition
  number, ranges), the figures, the stability/range table and an Allan summary.
"""

from __future__ import annotations

import datetime as dt
import html
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter
from numpy.typing import NDArray

from fog_temp_comp import __version__
from fog_temp_comp.core.coefficients import model_equation
from fog_temp_comp.core.evaluate import Score
from fog_temp_comp.core.fitstats import AxisFitStats
from fog_temp_comp.core.metrics import window_means
from fog_temp_comp.core.model import DriftModel, coefficient_key
from fog_temp_comp.core.units import AXES, DEG_H_PER_RAD_S, S_PER_H

FloatArray = NDArray[np.float64]

#: averaging window of the time-series plots (s), the paper's 10 s
PLOT_WINDOW_S = 10.0
#: averaging window of the temperature trace in the time-series plots (s)
TEMPERATURE_WINDOW_S = 60.0
#: IEEE Std 952 Annex C: bias instability = minimum of the Allan deviation / 0.664 (flicker)
BIAS_INSTABILITY_FACTOR = 0.664
#: fewest samples for which an Allan deviation is computed
MIN_ALLAN_SAMPLES = 16
_DPI = 100


class ReportRun(NamedTuple):
    """One evaluated run; a plain tuple in this order works as well.

    Attributes
    ----------
    name : str
        Run (bag) name, used in titles and file names.
    stamps_s : ndarray, shape (N,)
        Gyro stamps (s), non-decreasing.
    raw_rad_s, corrected_rad_s : ndarray, shape (N, 3)
        Gyro rates before and after compensation (rad/s).
    temp_stamps_s : ndarray, shape (M,)
        Temperature stamps (s).
    temperature_degC : ndarray, shape (M,)
        Gyro temperature (degC).

    """

    name: str
    stamps_s: FloatArray
    raw_rad_s: FloatArray
    corrected_rad_s: FloatArray
    temp_stamps_s: FloatArray
    temperature_degC: FloatArray


@dataclass(frozen=True)
class AllanCurve:
    """Overlapping Allan deviation of one axis, deg/h, at averaging times ``taus_s`` (s)."""

    taus_s: FloatArray
    adev_deg_h: FloatArray

    @property
    def minimum(self) -> tuple[float, float]:
        """``(tau_s, adev_deg_h)`` at the minimum (NaN if empty)."""
        if self.adev_deg_h.size == 0:
            return math.nan, math.nan
        k = int(np.argmin(self.adev_deg_h))
        return float(self.taus_s[k]), float(self.adev_deg_h[k])


def allan_deviation(stamps_s: FloatArray, rate_deg_h: FloatArray) -> AllanCurve:
    """Overlapping Allan deviation (``allantools.oadev``, octave taus) of a rate record.

    Parameters
    ----------
    stamps_s : ndarray, shape (N,)
        Stamps (s); the sample rate is taken as 1 / median spacing (gaps are not filled).
    rate_deg_h : ndarray, shape (N,)
        Angular rate (deg/h), treated as frequency data.

    Returns
    -------
    AllanCurve
        Empty for fewer than :data:`MIN_ALLAN_SAMPLES` samples.

    """
    import allantools  # imported here: only the report needs it

    t = np.asarray(stamps_s, dtype=np.float64)
    x = np.asarray(rate_deg_h, dtype=np.float64)
    if t.size < MIN_ALLAN_SAMPLES:
        return AllanCurve(np.empty(0), np.empty(0))
    spacing = float(np.median(np.diff(t)))
    if not spacing > 0:
        raise ValueError('gyro stamps do not advance; cannot compute an Allan deviation')
    taus, adev, _, _ = allantools.oadev(x, rate=1.0 / spacing, data_type='freq', taus='octave')
    taus, adev = np.asarray(taus, dtype=np.float64), np.asarray(adev, dtype=np.float64)
    keep = np.isfinite(adev) & (adev > 0)
    return AllanCurve(taus[keep], adev[keep])


def write_report(
    out_dir: str | Path,
    *,
    table: Any,
    model: DriftModel,
    fits: Sequence[AxisFitStats],
    runs: Sequence[ReportRun | tuple[Any, ...]],
    scores: Sequence[Score],
    warnings: Sequence[str] = (),
    context: Mapping[str, str] | None = None,
    title: str = 'FOG temperature-drift calibration',
) -> Path:
    """Write the PNG plots and ``index.html`` into ``out_dir`` (created if missing).

    Parameters
    ----------
    out_dir : str or Path
        Output directory; existing files of the same names are overwritten.
    table : fog_temp_comp.core.calibration.GridTable
        Calibration rows: ``temperature_degC`` (K,), ``tdot_degC_per_min`` (K,), ``rate_deg_h``
        (K, 3), as fitted (Earth rate already removed if it was).
    model : DriftModel
        The fitted model written to the coefficients file.
    fits : sequence of AxisFitStats
        Per-axis fit statistics of the same fit (x, y, z).
    runs : sequence of ReportRun or tuples in its field order
        Runs evaluated before/after compensation (may be empty).
    scores : sequence of Score
        Stability/range scores of those runs (may be empty).
    warnings : sequence of str
        Shown prominently at the top (e.g. ill-conditioning).
    context : mapping of str to str, optional
        Extra facts listed under the title (bags, denoising, Earth-rate removal, ...).
    title : str
        Page title.

    Returns
    -------
    Path
        The ``index.html`` written.

    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    temp = np.asarray(table.temperature_degC, dtype=np.float64)
    tdot = np.asarray(table.tdot_degC_per_min, dtype=np.float64)
    rate = np.asarray(table.rate_deg_h, dtype=np.float64)
    figures = _fit_figures(out, temp, tdot, rate, model, fits)
    allan: list[tuple[str, list[AllanCurve], list[AllanCurve]]] = []
    used: set[str] = set()
    for run_tuple in runs:
        run = ReportRun(*run_tuple)
        run_figures, before, after = _run_figures(out, run, _slug(run.name, used))
        figures += run_figures
        allan.append((run.name, before, after))
    page = _html_page(
        title=title,
        model=model,
        fits=fits,
        temp=temp,
        tdot=tdot,
        figures=figures,
        scores=scores,
        allan=allan,
        warnings=warnings,
        context=context or {},
    )
    index = out / 'index.html'
    index.write_text(page, encoding='utf-8')
    return index


def _fit_figures(
    out: Path,
    temp: FloatArray,
    tdot: FloatArray,
    rate: FloatArray,
    model: DriftModel,
    fits: Sequence[AxisFitStats],
) -> list[tuple[str, str, str]]:
    """Plot the fit (drift against temperature, residuals); (file name, heading, caption) each."""
    name = 'drift_vs_temperature.png'
    _plot_drift_vs_temperature(out / name, temp, tdot, rate, model)
    figures = [
        (
            name,
            'Drift against temperature',
            'Gyro 10 s means used in the fit (dots, coloured by Tdot) and the fitted model at '
            'the same temperature and Tdot (black). The dashed line is the model at Tdot = 0; '
            'the loops around it are the Tdot term.',
        )
    ]
    name = 'residual_histogram.png'
    _plot_residuals(out / name, fits)
    figures.append(
        (
            name,
            'Fit residuals',
            'Histogram of measured minus modelled drift on the 10 s grid, with the normal '
            'density of the same standard deviation.',
        )
    )
    return figures


def _run_figures(
    out: Path, run: ReportRun, slug: str
) -> tuple[list[tuple[str, str, str]], list[AllanCurve], list[AllanCurve]]:
    """Plot one run before/after compensation; its figures and Allan curves (before, after)."""
    stamps = np.asarray(run.stamps_s, dtype=np.float64)
    raw = np.asarray(run.raw_rad_s, dtype=np.float64) * DEG_H_PER_RAD_S
    corrected = np.asarray(run.corrected_rad_s, dtype=np.float64) * DEG_H_PER_RAD_S
    name = f'timeseries_{slug}.png'
    _plot_timeseries(out / name, run, stamps, raw, corrected)
    figures = [
        (
            name,
            f'{run.name}: before and after compensation',
            f'{PLOT_WINDOW_S:g} s means of the gyro output before (raw) and after '
            'compensation, each with its own mean removed (means in the panel titles), '
            'and the gyro temperature (right axis).',
        )
    ]
    before = [allan_deviation(stamps, raw[:, j]) for j in range(len(AXES))]
    after = [allan_deviation(stamps, corrected[:, j]) for j in range(len(AXES))]
    if any(c.taus_s.size for c in before + after):
        name = f'allan_{slug}.png'
        _plot_allan(out / name, run.name, before, after)
        figures.append(
            (
                name,
                f'{run.name}: Allan deviation',
                'Overlapping Allan deviation (IEEE Std 952, octave-spaced averaging times) '
                'before and after compensation. Temperature drift shows as the rise at '
                'long averaging times; compensation should bring it down. The longest '
                'averaging times rest on few averages and are uncertain.',
            )
        )
    return figures, before, after


# -- plots -------------------------------------------------------------------------------------


def _new_figure(rows: int, cols: int, size: tuple[float, float], **kw: Any) -> tuple[Figure, Any]:
    fig = Figure(figsize=size, dpi=_DPI, layout='constrained')
    axes = fig.subplots(rows, cols, squeeze=False, **kw)
    return fig, axes


def _plot_drift_vs_temperature(
    path: Path, temp: FloatArray, tdot: FloatArray, rate: FloatArray, model: DriftModel
) -> None:
    fig, axes = _new_figure(3, 1, (9.0, 9.5), sharex=True)
    predicted = model.drift_deg_h(temp, tdot)
    limit = float(np.max(np.abs(tdot))) or 1.0
    grid = np.linspace(float(temp.min()), float(temp.max()), 200)
    at_zero = model.drift_deg_h(grid, np.zeros_like(grid))
    scatter = None
    for j, axis in enumerate(AXES):
        ax = axes[j, 0]
        scatter = ax.scatter(
            temp, rate[:, j], c=tdot, s=6, cmap='coolwarm', vmin=-limit, vmax=limit,
            label='measured (10 s means)', rasterized=True,
        )  # fmt: skip
        ax.plot(temp, predicted[:, j], '.', color='black', ms=1.5, label='model at (T, Tdot)')
        ax.plot(grid, at_zero[:, j], '--', color='0.35', lw=1.2, label='model at Tdot = 0')
        ax.set_ylabel(f'{axis} drift [deg/h]')
        ax.set_title(f'{axis} axis', loc='left', fontsize=10)
        ax.grid(True, alpha=0.3)
        if j == 0:
            ax.legend(loc='best', fontsize=8, markerscale=3)
    axes[-1, 0].set_xlabel('gyro temperature T [degC]')
    if scatter is not None:
        fig.colorbar(scatter, ax=axes[:, 0].tolist(), label='Tdot [degC/min]', shrink=0.6)
    fig.suptitle('Gyro drift against temperature, with the fitted model')
    fig.savefig(path)


def _plot_residuals(path: Path, fits: Sequence[AxisFitStats]) -> None:
    fig, axes = _new_figure(1, len(fits), (4.0 * len(fits), 3.8))
    for k, f in enumerate(fits):
        ax = axes[0, k]
        resid = f.residuals
        bins = int(np.clip(np.sqrt(resid.size), 10, 60))
        ax.hist(resid, bins=bins, density=True, color='tab:blue', alpha=0.6, label='residuals')
        sd = float(np.std(resid))
        if sd > 0:
            xs = np.linspace(float(resid.min()), float(resid.max()), 200)
            pdf = np.exp(-0.5 * (xs / sd) ** 2) / (sd * math.sqrt(2 * math.pi))
            ax.plot(xs, pdf, color='black', lw=1.2, label=f'normal, std {sd:.4f}')
        ax.set_xlabel(f'{f.axis} residual [deg/h]')
        ax.set_ylabel('density [1/(deg/h)]')
        ax.set_title(
            f'{f.axis} axis: residual std {f.residual_std:.4f} deg/h, n = {f.n_samples}',
            fontsize=9,
        )
        ax.legend(fontsize=8)
        ax.grid(True, alpha=0.3)
    fig.suptitle('Fit residuals (measured - model) on the 10 s grid')
    fig.savefig(path)


def _plot_timeseries(
    path: Path, run: ReportRun, stamps: FloatArray, raw: FloatArray, corrected: FloatArray
) -> None:
    t0 = float(stamps[0]) if stamps.size else 0.0
    t_mid = window_means(stamps, stamps, PLOT_WINDOW_S)
    before = window_means(stamps, raw, PLOT_WINDOW_S)
    after = window_means(stamps, corrected, PLOT_WINDOW_S)
    temp_stamps = np.asarray(run.temp_stamps_s, dtype=np.float64)
    temp_values = np.asarray(run.temperature_degC, dtype=np.float64)
    temp_t = (window_means(temp_stamps, temp_stamps, TEMPERATURE_WINDOW_S) - t0) / S_PER_H
    temp = window_means(temp_stamps, temp_values, TEMPERATURE_WINDOW_S)
    hours = (t_mid - t0) / S_PER_H
    fig, axes = _new_figure(3, 1, (10.0, 9.5), sharex=True)
    handles: list[Any] = []
    for j, axis in enumerate(AXES):
        ax = axes[j, 0]
        mb, ma = float(before[:, j].mean()), float(after[:, j].mean())
        twin = ax.twinx()  # temperature behind the gyro traces
        ax.set_zorder(twin.get_zorder() + 1)
        ax.patch.set_visible(False)
        (h_temp,) = twin.plot(temp_t, temp, color='tab:red', lw=1.0, alpha=0.5)
        twin.set_ylabel('temperature [degC]', color='tab:red')
        twin.tick_params(axis='y', colors='tab:red')
        (h_raw,) = ax.plot(hours, before[:, j] - mb, color='tab:orange', lw=0.8)
        (h_cor,) = ax.plot(hours, after[:, j] - ma, color='tab:blue', lw=0.8)
        ax.set_ylabel(f'{axis} rate - its mean [deg/h]')
        ax.set_title(
            f'{axis} axis (means: raw {mb:+.4f} deg/h, compensated {ma:+.4f} deg/h)',
            loc='left',
            fontsize=10,
        )
        ax.grid(True, alpha=0.3)
        handles = [h_raw, h_cor, h_temp]
    axes[-1, 0].set_xlabel('time since start of run [h]')
    fig.legend(
        handles,
        [
            'raw (before), mean removed',
            'compensated (after), mean removed',
            f'temperature ({TEMPERATURE_WINDOW_S:g} s means, right axis)',
        ],
        loc='outside lower center',
        ncols=3,
        fontsize=9,
    )
    fig.suptitle(f'{run.name}: gyro output in {PLOT_WINDOW_S:g} s means, before and after')
    fig.savefig(path)


def _plot_allan(
    path: Path, name: str, before: Sequence[AllanCurve], after: Sequence[AllanCurve]
) -> None:
    fig, axes = _new_figure(1, len(AXES), (13.0, 4.4))
    for j, axis in enumerate(AXES):
        ax = axes[0, j]
        for curve, label, color in (
            (before[j], 'before (raw)', 'tab:orange'),
            (after[j], 'after (compensated)', 'tab:blue'),
        ):
            if curve.taus_s.size:
                ax.loglog(curve.taus_s, curve.adev_deg_h, 'o-', ms=3, color=color, label=label)
        tau_min, adev_min = after[j].minimum
        if math.isfinite(adev_min):
            ax.plot([tau_min], [adev_min], 'k*', ms=9,
                    label=f'min after: {adev_min:.4f} deg/h at {tau_min:g} s')  # fmt: skip
        ax.set_xlabel('averaging time tau [s]')
        ax.set_ylabel(f'{axis} Allan deviation [deg/h]')
        ax.xaxis.set_major_formatter(FuncFormatter(_plain_number))
        ax.yaxis.set_major_formatter(FuncFormatter(_plain_number))
        ax.yaxis.set_minor_formatter(FuncFormatter(_minor_label))
        ax.set_title(f'{axis} axis', fontsize=10)
        ax.grid(True, which='both', alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f'{name}: overlapping Allan deviation before and after compensation')
    fig.savefig(path)


def _plain_number(value: float, _pos: object = None) -> str:
    return f'{value:g}'


def _minor_label(value: float, _pos: object = None) -> str:
    """Label minor log ticks at 2 and 5 times a power of ten only."""
    if value <= 0:
        return ''
    mantissa = value / 10 ** math.floor(math.log10(value) + 1e-9)
    return (
        f'{value:g}'
        if round(mantissa) in (2, 5) and abs(mantissa - round(mantissa)) < 1e-6
        else ''
    )


def _slug(name: str, used: set[str]) -> str:
    base = re.sub(r'[^A-Za-z0-9_.-]+', '_', Path(str(name)).name).strip('._') or 'run'
    slug, k = base, 2
    while slug in used:
        slug, k = f'{base}_{k}', k + 1
    used.add(slug)
    return slug


# -- HTML --------------------------------------------------------------------------------------

_CSS = """
body { font-family: sans-serif; margin: 2em auto; max-width: 1100px; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; font-size: 0.9em; }
th, td { border: 1px solid #bbb; padding: 0.25em 0.6em; text-align: right; }
th { background: #eee; } td.l, th.l { text-align: left; }
.se { color: #555; } td.c { white-space: nowrap; }
.warn { background: #fff3cd; border: 1px solid #e0b100; padding: 0.5em 1em; }
figure { margin: 1em 0 2em; } img { max-width: 100%; }
figcaption { font-size: 0.9em; color: #444; } code { background: #f4f4f4; }
"""


def _e(value: object) -> str:
    return html.escape(str(value), quote=True)


def format_coefficient(value: float) -> str:
    """How a coefficient appears in the report (6 significant digits)."""
    return f'{value:.6g}'


def format_se(value: float) -> str:
    """How a standard error appears in the report (2 significant digits)."""
    return f'{value:.2g}'


def _html_page(
    *,
    title: str,
    model: DriftModel,
    fits: Sequence[AxisFitStats],
    temp: FloatArray,
    tdot: FloatArray,
    figures: Sequence[tuple[str, str, str]],
    scores: Sequence[Score],
    allan: Sequence[tuple[str, list[AllanCurve], list[AllanCurve]]],
    warnings: Sequence[str],
    context: Mapping[str, str],
) -> str:
    created = dt.datetime.now(dt.UTC).strftime('%Y-%m-%d %H:%M:%SZ')
    out = [
        '<!DOCTYPE html>',
        '<html lang="en"><head><meta charset="utf-8">',
        f'<title>{_e(title)}</title><style>{_CSS}</style></head><body>',
        f'<h1>{_e(title)}</h1>',
        f'<p>Created {created} by fog_temp_comp {_e(__version__)}.</p>',
    ]
    if context:
        out.append('<table>')
        out += [f'<tr><th class="l">{_e(k)}</th><td class="l">{_e(v)}</td></tr>'
                for k, v in context.items()]  # fmt: skip
        out.append('</table>')
    if warnings:
        out.append('<div class="warn"><strong>Warnings</strong><ul>')
        out += [f'<li>{_e(w)}</li>' for w in warnings]
        out.append('</ul></div>')
    out.append('<h2>Fit</h2>')
    out.append(f'<p>Model: <code>{_e(model_equation(model.terms))}</code></p>')
    out.append(_fit_table(model, fits))
    out.append(_range_table(model, temp, tdot))
    for name, heading, caption in figures:
        out.append(
            f'<figure id="{_e(name)}"><h3>{_e(heading)}</h3>'
            f'<a href="{_e(name)}"><img src="{_e(name)}" alt="{_e(heading)}"></a>'
            f'<figcaption>{_e(caption)}</figcaption></figure>'
        )
    if scores:
        out.append('<h2>Bias stability and range, before and after compensation</h2>')
        out.append(_score_table(scores))
    if allan:
        out.append('<h2>Allan deviation summary</h2>')
        out.append(_allan_table(allan))
    out.append('</body></html>')
    return '\n'.join(out) + '\n'


def _fit_table(model: DriftModel, fits: Sequence[AxisFitStats]) -> str:
    head = ''.join(
        f'<th>{_e(coefficient_key(t))}<br><span class="se">&plusmn; SE (Newey-West)</span></th>'
        for t in model.terms
    )
    rows = [
        '<table><tr><th class="l">axis</th>' + head + '<th>R&sup2;</th>'
        '<th>residual std [deg/h]</th><th>condition number</th><th>n (10 s rows)</th>'
        '<th>HAC lags</th></tr>'
    ]
    for j, f in enumerate(fits):
        cells = []
        for i, term in enumerate(model.terms):
            value = float(model.coefficients[i, j])
            k = f.names.index(term)  # the fit may have more terms (e.g. const, not written)
            cells.append(
                f'<td class="c">{format_coefficient(value)} &plusmn; '
                f'{format_se(float(f.se_hac[k]))}'
                f'<br><span class="se">classical &plusmn; '
                f'{format_se(float(f.se_classical[k]))}</span></td>'
            )
        rows.append(
            f'<tr><td class="l">{_e(f.axis)}</td>{"".join(cells)}'
            f'<td>{f.r_squared:.4f}</td><td>{f.residual_std:.4f}</td>'
            f'<td>{f.condition_number:.1f}</td><td>{f.n_samples}</td><td>{f.hac_lag}</td></tr>'
        )
    rows.append('</table>')
    rows.append(
        '<p class="se">Standard errors: Newey-West (HAC, Bartlett kernel), the ones written to '
        'the coefficients file; the classical ones below them assume uncorrelated residuals '
        'and are too small when the gyro bias wanders. Condition number: of the design with '
        'every column scaled to unit norm (above 30: the terms trade off).</p>'
    )
    return '\n'.join(rows)


def _range_table(model: DriftModel, temp: FloatArray, tdot: FloatArray) -> str:
    t_r, r_r = model.temperature_range_degC, model.tdot_range_degC_per_min
    return (
        '<table><tr><th class="l">calibrated range</th><th>low</th><th>high</th>'
        '<th>span</th></tr>'
        f'<tr><td class="l">temperature [degC]</td><td>{t_r.low:.2f}</td>'
        f'<td>{t_r.high:.2f}</td><td>{t_r.high - t_r.low:.2f}</td></tr>'
        f'<tr><td class="l">Tdot [degC/min]</td><td>{r_r.low:.3f}</td>'
        f'<td>{r_r.high:.3f}</td><td>{r_r.high - r_r.low:.3f}</td></tr>'
        f'<tr><td class="l">grid rows</td><td colspan="3">{temp.size}</td></tr></table>'
    )


def _ratio(after: float, before: float) -> str:
    return f'{after / before:.2f}' if before > 0 else 'n/a'


def _score_table(scores: Sequence[Score]) -> str:
    rows = [
        '<table><tr><th class="l">run</th><th class="l">axis</th><th>tau [s]</th>'
        '<th>stability before [deg/h]</th><th>stability after [deg/h]</th><th>after/before</th>'
        '<th>range before [deg/h]</th><th>range after [deg/h]</th><th>after/before</th></tr>'
    ]
    for s in scores:
        rows.append(
            f'<tr><td class="l">{_e(s.run)}</td><td class="l">{_e(s.axis)}</td>'
            f'<td>{s.tau_s:g}</td><td>{s.stability_before_deg_h:.4f}</td>'
            f'<td>{s.stability_after_deg_h:.4f}</td>'
            f'<td>{_ratio(s.stability_after_deg_h, s.stability_before_deg_h)}</td>'
            f'<td>{s.range_before_deg_h:.4f}</td><td>{s.range_after_deg_h:.4f}</td>'
            f'<td>{_ratio(s.range_after_deg_h, s.range_before_deg_h)}</td></tr>'
        )
    rows.append('</table>')
    rows.append(
        '<p class="se">Stability: standard deviation of tau-second means; range: max - min of '
        "tau-second means (GJB 2426A, the paper's Tables 2 and 3).</p>"
    )
    return '\n'.join(rows)


def _tau_cell(curve: AllanCurve, tau_s: float) -> str:
    """``tau`` of a minimum, flagged when it is the longest tau (no minimum seen)."""
    last = curve.taus_s.size > 0 and tau_s == float(curve.taus_s[-1])
    return f'{tau_s:g} (longest)' if last else f'{tau_s:g}'


def _allan_table(allan: Sequence[tuple[str, list[AllanCurve], list[AllanCurve]]]) -> str:
    rows = [
        '<table><tr><th class="l">run</th><th class="l">axis</th>'
        '<th>min ADEV before [deg/h]</th><th>at tau [s]</th>'
        '<th>min ADEV after [deg/h]</th><th>at tau [s]</th>'
        '<th>bias instability after [deg/h]</th></tr>'
    ]
    for name, before, after in allan:
        for j, axis in enumerate(AXES):
            tb, ab = before[j].minimum
            ta, aa = after[j].minimum
            rows.append(
                f'<tr><td class="l">{_e(name)}</td><td class="l">{axis}</td>'
                f'<td>{ab:.4f}</td><td>{_tau_cell(before[j], tb)}</td><td>{aa:.4f}</td>'
                f'<td>{_tau_cell(after[j], ta)}</td>'
                f'<td>{aa / BIAS_INSTABILITY_FACTOR:.4f}</td></tr>'
            )
    rows.append('</table>')
    rows.append(
        '<p class="se">Bias instability = minimum Allan deviation / 0.664 (IEEE Std 952, '
        'Annex C). A minimum at the longest tau (marked) means the record is too short to '
        'see the bias instability: the value is then only an upper bound.</p>'
    )
    return '\n'.join(rows)
