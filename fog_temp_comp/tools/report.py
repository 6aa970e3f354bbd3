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

The Allan deviation is computed in :mod:`~fog_temp_comp.tools.report_allan`, the figures drawn
in :mod:`~fog_temp_comp.tools.report_plots` and the page written by
:mod:`~fog_temp_comp.tools.report_html`; their public names are re-exported here.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fog_temp_comp.core.evaluate import Score
from fog_temp_comp.core.fitstats import AxisFitStats
from fog_temp_comp.core.model import DriftModel
from fog_temp_comp.tools.report_allan import (
    BIAS_INSTABILITY_FACTOR,
    MIN_ALLAN_SAMPLES,
    AllanCurve,
    allan_deviation,
)
from fog_temp_comp.tools.report_html import format_coefficient, format_se, html_page
from fog_temp_comp.tools.report_plots import (
    PLOT_WINDOW_S,
    TEMPERATURE_WINDOW_S,
    ReportRun,
    plot_fit,
    plot_run,
    unique_slug,
)

__all__ = [
    'BIAS_INSTABILITY_FACTOR',
    'MIN_ALLAN_SAMPLES',
    'PLOT_WINDOW_S',
    'TEMPERATURE_WINDOW_S',
    'AllanCurve',
    'ReportRun',
    'allan_deviation',
    'format_coefficient',
    'format_se',
    'write_report',
]

FloatArray = NDArray[np.float64]


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
    figures = plot_fit(out, temp, tdot, rate, model, fits)
    allan: list[tuple[str, list[AllanCurve], list[AllanCurve]]] = []
    used: set[str] = set()
    for run_tuple in runs:
        run = ReportRun(*run_tuple)
        run_figures, before, after = plot_run(out, run, unique_slug(run.name, used))
        figures += run_figures
        allan.append((run.name, before, after))
    page = html_page(
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
