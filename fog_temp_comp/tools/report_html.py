"""The calibration report's ``index.html``: self-contained page and its tables.

Fit table (coefficients +- standard errors, R^2, residual std, condition number), the
calibrated range, the stability/range table (deg/h) and the Allan summary.
"""

from __future__ import annotations

import datetime as dt
import html
import math
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp import __version__
from fog_temp_comp.core.coefficients import model_equation
from fog_temp_comp.core.evaluate import Score
from fog_temp_comp.core.fitstats import AxisFitStats
from fog_temp_comp.core.model import DriftModel, coefficient_key
from fog_temp_comp.core.units import AXES
from fog_temp_comp.tools.report_allan import BIAS_INSTABILITY_FACTOR, AllanCurve

FloatArray = NDArray[np.float64]

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


def html_page(
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
    """The whole ``index.html`` text: context, warnings, fit, figures and the tables."""
    created = dt.datetime.now(dt.timezone.utc).strftime('%Y-%m-%d %H:%M:%SZ')
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


def _ratio(ratio: float) -> str:
    return 'n/a' if math.isnan(ratio) else f'{ratio:.2f}'


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
            f'<td>{_ratio(s.ratio("stability"))}</td>'
            f'<td>{s.range_before_deg_h:.4f}</td><td>{s.range_after_deg_h:.4f}</td>'
            f'<td>{_ratio(s.ratio("range"))}</td></tr>'
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
