"""Least squares that knows the gyro's wandering bias: prewhitened (GLS) drift fits.

The residual of a chamber fit on the 10 s grid is not white. Besides the white rate noise
(angle random walk) the bias wanders (bias instability, rate random walk; IEEE Std 952), and
over a 20 h run a rate random walk of 0.003 deg/h/sqrt(h) moves the bias by ~0.015 deg/h.
Ordinary least squares gives every row the same weight, so the part of that slow wander that
happens to correlate with T (a cycle is one slow swing) is taken for a temperature coefficient,
and a fit that is unbiased on average is off by as much as the wander on any one run.

Generalised least squares weighs the rows by the noise's own correlation instead. Per axis the
residual is modelled as white noise plus a random walk, ``e_t = w_t + b_t`` with
``var(w) = s_w2`` and ``var(b_t - b_{t-1}) = s_b2`` (deg^2/h^2 per row). Its difference is an
MA(1) process, ``e_t - e_{t-1} = u_t - theta u_{t-1}``, so filtering both sides of the regression
by ``(1 - L) / (1 - theta L)`` whitens it (:func:`prewhiten`); the filter restarts wherever the
grid breaks (a gap, a new bag, a held-out block). ``s_w2`` and ``s_b2`` come from the OLS
residual itself: ``var(e_{t+k} - e_t) = 2 s_w2 + k s_b2`` over k = 1..64 rows
(:func:`walk_noise`), and the fit is iterated once with the GLS residual. Without a random walk
``theta`` is 1 and the fit is OLS exactly. The constant is re-estimated last as the mean
residual (a random walk leaves the level, not the slopes, uncertain).

On the accuracy study's plants, with the true coil temperature, this takes the 100 s stability
of a fit on one 20 h cycle from 1.2-1.7x to 1.0-1.3x that of the oracle wherever the bias
wanders (``benchmarks/accuracy.py``).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fog_temp_comp.core.fitstats import AxisFitStats, fit_ols

FloatArray = NDArray[np.float64]

__all__ = [
    'DIFFERENCE_LAGS',
    'WalkNoise',
    'fit_gls',
    'gls_coefficients',
    'prewhiten',
    'segment_starts',
    'walk_noise',
]

#: lags (grid rows) of the difference variances that measure the noise model
DIFFERENCE_LAGS = (1, 2, 4, 8, 16, 32, 64)
#: theta at or above this is no random walk worth modelling: plain OLS
THETA_OLS = 0.9999
#: a random walk is modelled only where its slope in the difference variances exceeds this many
#: standard errors (of white noise alone)
SIGNIFICANCE = 3.0


@dataclass(frozen=True)
class WalkNoise:
    """White noise plus a random walk, per grid row: variances in (response unit)^2."""

    white_var: float
    walk_var: float

    @property
    def theta(self) -> float:
        """MA(1) coefficient of the differenced noise, in (0, 1] (1: no random walk)."""
        if not self.walk_var > 0.0:
            return 1.0
        if not self.white_var > 0.0:
            return 0.0
        rho = self.white_var / (self.walk_var + 2.0 * self.white_var)  # -lag-1 autocorrelation
        return (1.0 - math.sqrt(max(1.0 - 4.0 * rho * rho, 0.0))) / (2.0 * rho)


def segment_starts(bin_index: ArrayLike | None, n: int) -> NDArray[np.intp]:
    """Row numbers where a run of consecutive grid bins starts (always includes 0).

    Parameters
    ----------
    bin_index : array_like of int, shape (n,), or None
        Absolute grid bin of each row; None: one unbroken run.
    n : int
        Number of rows.

    """
    if bin_index is None or n == 0:
        return np.zeros(1 if n else 0, dtype=np.intp)
    idx = np.asarray(bin_index, dtype=np.int64)
    if idx.shape != (n,):
        raise ValueError(f'bin_index must have shape ({n},), got {idx.shape}')
    return np.flatnonzero(np.r_[True, np.diff(idx) != 1])


def walk_noise(
    residuals: ArrayLike, starts: ArrayLike, lags: Sequence[int] = DIFFERENCE_LAGS
) -> WalkNoise:
    """White and random-walk variances of a residual, from its k-row difference variances.

    Least squares of ``var(e_{t+k} - e_t)`` on ``2 s_w2 + k s_b2`` over ``lags``, differences
    taken within segments only; negative estimates are set to 0, and so is a walk whose slope
    is within :data:`SIGNIFICANCE` standard errors of 0.

    Parameters
    ----------
    residuals : array_like, shape (n,)
        Fit residuals on the grid.
    starts : array_like of int
        Segment starts (:func:`segment_starts`).
    lags : sequence of int
        Difference lags, rows.

    """
    e = np.asarray(residuals, dtype=np.float64)
    bounds = [*np.asarray(starts, dtype=np.intp).tolist(), e.size]
    used, values, counts = [], [], []
    for k in lags:
        total, count = 0.0, 0
        for lo, hi in itertools.pairwise(bounds):
            if hi - lo > k:
                d = e[lo + k : hi] - e[lo : hi - k]
                total += float(d @ d)
                count += d.size
        if count >= 10:
            used.append(k)
            values.append(total / count)
            counts.append(count)
    if len(used) < 2:
        return WalkNoise(float(np.var(e)) if e.size else 0.0, 0.0)
    a = np.stack([np.full(len(used), 2.0), np.asarray(used, dtype=np.float64)], axis=1)
    v = np.asarray(values)
    (white2, walk), *_ = np.linalg.lstsq(a, v, rcond=None)
    # a walk must stand out of the sampling error the variances would have under white noise
    # alone (lag-k differences of white noise: variance 2 s^2, standard error ~ 2 s^2
    # sqrt(3 / m) over m differences, taken as independent between lags)
    level = float(np.mean(v))
    weights = np.asarray(counts, dtype=np.float64) / (3.0 * level * level) if level > 0 else None
    if weights is not None:
        se = math.sqrt(float(np.linalg.inv(a.T @ (a * weights[:, None]))[1, 1]))
        if not walk > SIGNIFICANCE * se:
            return WalkNoise(level / 2.0, 0.0)
    return WalkNoise(max(float(white2), 0.0), max(float(walk), 0.0))


def prewhiten(values: ArrayLike, theta: float, starts: ArrayLike) -> FloatArray:
    """``(1 - L) / (1 - theta L)`` along axis 0, restarted at each segment start.

    Each segment starts from rest (its first row passes unchanged), so a constant column keeps
    a decaying trace of its level; ``theta`` = 1 returns the input. The same filter as
    ``scipy.signal.lfilter([1, -1], [1, -theta], segment, axis=0)`` (to rounding; tested),
    without importing scipy.signal (about 1 s of a command's start-up).
    """
    x = np.asarray(values, dtype=np.float64)
    if theta >= THETA_OLS:
        return x.copy()
    bounds = [*np.asarray(starts, dtype=np.intp).tolist(), x.shape[0]]
    out = np.empty_like(x)
    for lo, hi in itertools.pairwise(bounds):
        d = np.diff(x[lo:hi], axis=0, prepend=np.zeros_like(x[lo : lo + 1]))
        out[lo:hi] = _decay_sum(d, theta)
    return out


#: a block of :func:`_decay_sum` keeps ``theta^-k`` below this (far from overflow)
_MAX_GROWTH = 1e100


def _decay_sum(d: FloatArray, theta: float) -> FloatArray:
    """``y_t = theta y_(t-1) + d_t`` along axis 0 from ``y_(-1) = 0``, ``0 <= theta < 1``.

    In blocks short enough that ``theta^-k`` stays below :data:`_MAX_GROWTH`: within a block
    ``y_(s+k) = theta^k (theta y_(s-1) + sum_(j<=k) theta^-j d_(s+j))``, whose rounding error
    is that of the largest ``|d|`` times the machine epsilon (the scaled terms come back down).
    """
    if theta <= 0.0:
        return d.copy()
    block = max(1, int(math.log(_MAX_GROWTH) / -math.log(theta)))
    out = np.empty_like(d)
    carry = np.zeros_like(d[:1])
    for lo in range(0, d.shape[0], block):
        hi = min(lo + block, d.shape[0])
        k = np.arange(hi - lo, dtype=np.float64).reshape((-1,) + (1,) * (d.ndim - 1))
        grow = theta**-k
        out[lo:hi] = (theta * carry + np.cumsum(d[lo:hi] * grow, axis=0)) / grow
        carry = out[hi - 1 : hi]
    return out


def _relevel(coef: FloatArray, design: FloatArray, y: FloatArray, const: int | None) -> None:
    """Set the constant (index ``const``) to the mean residual of the other terms, in place."""
    if const is None:
        return
    others = np.arange(design.shape[1]) != const
    coef[const] = float(np.mean(y - design[:, others] @ coef[others]))


def gls_coefficients(
    design: ArrayLike,
    y: ArrayLike,
    starts: ArrayLike,
    *,
    const: int | None = None,
    iterations: int = 2,
    thetas: Sequence[float] | None = None,
) -> tuple[FloatArray, list[float]]:
    """Coefficients (p, M) of the prewhitened fit of every column of ``y``, and each theta.

    The bare numbers of :func:`fit_gls` (no statistics): what cross-validation calls per fold.
    ``const`` is the column index of the constant term, if any. Given ``thetas`` (one per
    column), the filter is not re-estimated.
    """
    x = np.asarray(design, dtype=np.float64)
    yy = np.asarray(y, dtype=np.float64)
    yy = yy[:, None] if yy.ndim == 1 else yy
    coef = np.asarray(np.linalg.lstsq(x, yy, rcond=None)[0], dtype=np.float64)
    used = []
    for j in range(yy.shape[1]):
        b, theta = coef[:, j].copy(), 1.0
        for _ in range(1 if thetas is not None else iterations):
            theta = thetas[j] if thetas is not None else walk_noise(yy[:, j] - x @ b, starts).theta
            if theta >= THETA_OLS:
                break
            b = np.asarray(
                np.linalg.lstsq(
                    prewhiten(x, theta, starts), prewhiten(yy[:, j], theta, starts), rcond=None
                )[0],
                dtype=np.float64,
            )
            _relevel(b, x, yy[:, j], const)
        coef[:, j] = b
        used.append(theta)
    return coef, used


def fit_gls(
    design: ArrayLike,
    y: ArrayLike,
    *,
    names: Sequence[str],
    bin_index: ArrayLike | None = None,
    lag: int | None = None,
    axes: Sequence[str] | None = None,
    iterations: int = 2,
) -> list[AxisFitStats]:
    """Prewhitened least squares of every column of ``y`` on ``design``, with diagnostics.

    As :func:`fog_temp_comp.core.fitstats.fit_ols` (same arguments and checks), with the noise
    model of the module docstring per column. Standard errors are those of the whitened
    regression (Newey-West on the whitened residual); residuals, ``residual_std`` and R^2 are on
    the original rows; ``whitening_theta`` records the filter (1: OLS).

    Parameters
    ----------
    design : array_like, shape (N, p)
        Regressors.
    y : array_like, shape (N,) or (N, M)
        Responses (deg/h).
    names : sequence of str, length p
        Regressor names.
    bin_index : array_like of int, shape (N,), optional
        Absolute grid bin of each row: the whitening restarts where it is not consecutive.
    lag : int, optional
        Bartlett lags of the HAC standard errors (default: data-driven).
    axes : sequence of str, optional
        Column names.
    iterations : int
        Noise-model re-estimations (the first from the OLS residual).

    """
    ols = fit_ols(design, y, names=names, lag=lag, axes=axes)
    x = np.asarray(design, dtype=np.float64)
    yy = np.asarray(y, dtype=np.float64)
    yy = yy[:, None] if yy.ndim == 1 else yy
    starts = segment_starts(bin_index, x.shape[0])
    const = list(names).index('const') if 'const' in names else None
    coef, thetas = gls_coefficients(x, yy, starts, const=const, iterations=iterations)
    out = []
    for j, (fit, theta) in enumerate(zip(ols, thetas, strict=True)):
        if theta >= THETA_OLS:
            out.append(fit)
            continue
        (white,) = fit_ols(
            prewhiten(x, theta, starts),
            prewhiten(yy[:, j], theta, starts),
            names=names,
            lag=lag,
            axes=(fit.axis,),
        )
        b = coef[:, j]
        resid = yy[:, j] - x @ b
        n, p = x.shape
        sst = float(np.sum((yy[:, j] - yy[:, j].mean()) ** 2))
        ssr = float(resid @ resid)
        out.append(
            dataclasses.replace(
                white,
                coefficients=b,
                residuals=resid,
                residual_std=math.sqrt(ssr / (n - p)),
                r_squared=1.0 - ssr / sst if sst > 0 else math.nan,
                condition_number=fit.condition_number,
                whitening_theta=theta,
            )
        )
    return out
