"""The calibration report's PNG figures (matplotlib, Agg; no display needed).

Drift against temperature (deg/h, degC, coloured by Tdot in degC/min), the fit residuals,
and per run the 10 s means before/after compensation and the Allan deviations.
:class:`ReportRun` is one evaluated run as the report takes it.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import matplotlib
import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter
from numpy.typing import NDArray

from fog_temp_comp.core.fitstats import AxisFitStats
from fog_temp_comp.core.metrics import window_means
from fog_temp_comp.core.model import DriftModel
from fog_temp_comp.core.units import AXES, DEG_H_PER_RAD_S, S_PER_H
from fog_temp_comp.tools.report_allan import AllanCurve, allan_deviation

FloatArray = NDArray[np.float64]

#: averaging window of the time-series plots (s), the paper's 10 s
PLOT_WINDOW_S = 10.0
#: averaging window of the temperature trace in the time-series plots (s)
TEMPERATURE_WINDOW_S = 60.0
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


def plot_fit(
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


def plot_run(
    out: Path, run: ReportRun, slug: str
) -> tuple[list[tuple[str, str, str]], list[AllanCurve], list[AllanCurve]]:
    """Plot one run before/after compensation; its figures and Allan curves (before, after)."""
    stamps = np.asarray(run.stamps_s, dtype=np.float64)
    raw = np.asarray(run.raw_rad_s, dtype=np.float64) * DEG_H_PER_RAD_S
    corrected = np.asarray(run.corrected_rad_s, dtype=np.float64) * DEG_H_PER_RAD_S
    # rows the compensator dropped (gyro before the first temperature, a repeated stamp)
    keep = np.all(np.isfinite(corrected), axis=1)
    stamps, raw, corrected = stamps[keep], raw[keep], corrected[keep]
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
    save_options = _legend_below(
        fig,
        handles,
        [
            'raw (before), mean removed',
            'compensated (after), mean removed',
            f'temperature ({TEMPERATURE_WINDOW_S:g} s means, right axis)',
        ],
    )
    fig.suptitle(f'{run.name}: gyro output in {PLOT_WINDOW_S:g} s means, before and after')
    fig.savefig(path, **save_options)


def _legend_below(fig: Figure, handles: list[Any], labels: list[str]) -> dict[str, Any]:
    """One row of legend below the axes; the ``savefig`` options that keep it in the file.

    matplotlib 3.7 and later make room for it in the constrained layout; older ones (Ubuntu
    22.04's 3.5, what ROS 2 Humble users have) put it under the figure's edge, saved tight.
    """
    if tuple(int(part) for part in matplotlib.__version__.split('.')[:2]) >= (3, 7):
        fig.legend(handles, labels, loc='outside lower center', ncols=3, fontsize=9)
        return {}
    fig.legend(handles, labels, loc='upper center', bbox_to_anchor=(0.5, 0.0), ncol=3, fontsize=9)
    return {'bbox_inches': 'tight'}


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


def unique_slug(name: str, used: set[str]) -> str:
    """A file-name-safe form of run ``name``, not yet in ``used`` (added to it)."""
    base = re.sub(r'[^A-Za-z0-9_.-]+', '_', Path(str(name)).name).strip('._') or 'run'
    slug, k = base, 2
    while slug in used:
        slug, k = f'{base}_{k}', k + 1
    used.add(slug)
    return slug
