"""The fleet's view: outliers by a robust rule, and ``report/index.html`` with PNG plots.

:func:`outliers` flags a unit whose coefficient (or residual std, high side only) lies more than
:data:`OUTLIER_Z` robust z-scores from the fleet median (``0.6745 (x - median) / MAD``, the
modified z-score of Iglewicz and Hoaglin), over the calibrated units. :func:`write_fleet_report`
draws each coefficient's distribution across units and the residual std per unit, with the
outliers marked, and lists the failed units with their reasons.
"""

from __future__ import annotations

import datetime as dt
import html
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from fog_temp_comp import __version__
from fog_temp_comp.core.prior import MIN_OUTLIER_UNITS, OUTLIER_Z, robust_z
from fog_temp_comp.core.units import AXES

_DPI = 100


def _number(value: Any) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def coefficient_columns(rows: Sequence[dict[str, Any]]) -> list[str]:
    """The coefficient columns (``x_d0_deg_h``, ...) present in ``rows``, in order."""
    prefixes = tuple(f'{a}_' for a in AXES)
    out: dict[str, None] = {}
    for row in rows:
        for key in row:
            if key.startswith(prefixes) and not key.endswith(('_se', 'residual_std_deg_h')):
                out[key] = None
    return list(out)


def outliers(rows: Sequence[dict[str, Any]]) -> dict[str, str]:
    """Unit -> reason, for calibrated units beyond :data:`OUTLIER_Z` on some column."""
    ok = [r for r in rows if r.get('status') == 'ok']
    if len(ok) < MIN_OUTLIER_UNITS:
        return {}
    reasons: dict[str, list[str]] = {}
    columns = [(c, False) for c in coefficient_columns(ok)]
    columns += [(f'{a}_residual_std_deg_h', True) for a in AXES]
    for column, high_only in columns:
        have = [r for r in ok if math.isfinite(_number(r.get(column)))]
        if len(have) < MIN_OUTLIER_UNITS:
            continue
        values = np.array([_number(r[column]) for r in have])
        z = robust_z(values)
        median = float(np.median(values))
        for row, zk, value in zip(have, z, values, strict=True):
            if zk > OUTLIER_Z or (not high_only and zk < -OUTLIER_Z):
                reasons.setdefault(row['unit'], []).append(
                    f'{column} = {value:.4g} (fleet median {median:.4g}, robust z {zk:+.1f})'
                )
    return {unit: '; '.join(r) for unit, r in reasons.items()}


def write_fleet_report(out_dir: Path, rows: Sequence[dict[str, Any]]) -> Path:
    """Write PNGs and ``index.html`` for the fleet table ``rows``; return the index path."""
    out_dir.mkdir(parents=True, exist_ok=True)
    ok = [r for r in rows if r.get('status') == 'ok']
    figures = []
    columns = coefficient_columns(ok)
    keys = list(dict.fromkeys(c[2:] for c in columns))
    for key in keys:
        name = f'coefficient_{key}.png'
        _plot_distribution(out_dir / name, ok, key)
        figures.append((f'{key} across units (outliers in red)', name))
    if ok:
        _plot_residual_std(out_dir / 'residual_std.png', ok)
        figures.append(('residual std per unit (outliers in red)', 'residual_std.png'))
    index = out_dir / 'index.html'
    index.write_text(_page(rows, figures), encoding='utf-8')
    return index


def _plot_distribution(path: Path, rows: Sequence[dict[str, Any]], key: str) -> None:
    fig = Figure(figsize=(10, 3), dpi=_DPI, layout='constrained')
    for j, axis in enumerate(AXES):
        ax = fig.add_subplot(1, 3, j + 1)
        column = f'{axis}_{key}'
        good = [_number(r.get(column)) for r in rows if not r.get('outlier')]
        bad = [_number(r.get(column)) for r in rows if r.get('outlier')]
        good = [v for v in good if math.isfinite(v)]
        bad = [v for v in bad if math.isfinite(v)]
        if good:
            ax.hist(good, bins=min(30, max(5, len(good) // 3)), color='tab:blue')
        for v in bad:
            ax.axvline(v, color='tab:red', lw=1.5)
        ax.set_title(f'{axis}: {key}', fontsize=9)
        ax.set_ylabel('units')
    fig.savefig(path)


def _plot_residual_std(path: Path, rows: Sequence[dict[str, Any]]) -> None:
    n = len(rows)
    fig = Figure(figsize=(max(6.0, 0.12 * n + 2), 3.5), dpi=_DPI, layout='constrained')
    ax = fig.add_subplot(1, 1, 1)
    x = np.arange(n)
    for axis in AXES:
        values = [_number(r.get(f'{axis}_residual_std_deg_h')) for r in rows]
        ax.plot(x, values, 'o', ms=3, label=axis)
    for k, row in enumerate(rows):
        if row.get('outlier'):
            ax.axvspan(k - 0.5, k + 0.5, color='tab:red', alpha=0.2)
    ax.set_xticks(x, [str(r['unit']) for r in rows], rotation=90, fontsize=6)
    ax.set_ylabel('residual std, deg/h')
    ax.legend(fontsize=8)
    fig.savefig(path)


def _e(value: object) -> str:
    return html.escape(str(value))


def _page(rows: Sequence[dict[str, Any]], figures: Sequence[tuple[str, str]]) -> str:
    counts = {s: sum(r.get('status') == s for r in rows) for s in ('ok', 'failed', 'pending')}
    failed = [r for r in rows if r.get('status') != 'ok']
    flagged = [r for r in rows if r.get('outlier')]
    parts = [
        '<!DOCTYPE html><html><head><meta charset="utf-8"><title>Fleet calibration</title>',
        '<style>body{font-family:sans-serif;max-width:1100px;margin:auto}'
        'td,th{border:1px solid #ccc;padding:2px 6px;font-size:13px}'
        'table{border-collapse:collapse}</style></head><body>',
        '<h1>Fleet calibration</h1>',
        f'<p>{len(rows)} units: {counts["ok"]} calibrated, {counts["failed"]} failed'
        + (f', {counts["pending"]} not run' if counts['pending'] else '')
        + f'. fog_temp_comp {_e(__version__)}, '
        f'{dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")}.</p>',
        f'<h2>Outliers ({len(flagged)})</h2><p>Robust rule: modified z-score '
        f'0.6745 (x - median) / MAD beyond {OUTLIER_Z} on a coefficient, or above it on the '
        'residual std, over the calibrated units.</p>',
        _table(flagged, ('unit', 'outlier')),
        f'<h2>Failed units ({len(failed)})</h2>',
        _table(failed, ('unit', 'status', 'reason')),
    ]
    for title, name in figures:
        parts.append(f'<h2>{_e(title)}</h2><img src="{_e(name)}" alt="{_e(title)}">')
    parts.append('<p>Every value: <code>../fleet.csv</code>.</p></body></html>')
    return '\n'.join(parts)


def _table(rows: Sequence[dict[str, Any]], columns: Sequence[str]) -> str:
    if not rows:
        return '<p>none</p>'
    head = ''.join(f'<th>{_e(c)}</th>' for c in columns)
    body = ''.join(
        '<tr>' + ''.join(f'<td>{_e(r.get(c, ""))}</td>' for c in columns) + '</tr>' for r in rows
    )
    return f'<table><tr>{head}</tr>{body}</table>'
