"""First-order lag from the temperature sensor to the fibre coil.

The sensor sits on the housing, and the coil follows the housing with a thermal time constant
``tau`` (``coil_lag_s``): ``dT_coil/dt = (T_housing - T_coil) / tau``. The compensator feeds its
Tdot estimator's output (temperature and Tdot, each a stream of estimates with stamps) through
this lag, so the drift model sees coil temperature and coil rate. The lag is linear and
time-invariant, so lagging the rate estimate is the same as differentiating the lagged
temperature, and the estimator's own noise model (quantization, grid) stays valid.

Both the online :class:`CoilLag` and the offline :func:`coil_lag` are exact for an input that is
linear between samples (first-order hold), start in steady state on the first sample, and agree
to rounding.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fog_temp_comp.core.bounded_search import minimize_bounded

FloatArray = NDArray[np.float64]

__all__ = ['CoilLag', 'affine_scan', 'coil_lag', 'foh_lag_coefficients', 'search_time_constant']


def foh_lag_coefficients(dt_s: float, tau_s: float) -> tuple[float, float]:
    """Coefficients ``(a, b)`` of one exact first-order-hold step of the lag.

    ``y1 = a*y0 + (1 - a)*x0 + b*(x1 - x0)`` with ``a = exp(-dt/tau)`` and
    ``b = 1 - tau*(1 - a)/dt``.

    Parameters
    ----------
    dt_s : float
        Time between the two samples, s (> 0).
    tau_s : float
        Time constant, s (> 0).

    Returns
    -------
    tuple of float
        ``(a, b)``, dimensionless.

    """
    a = math.exp(-dt_s / tau_s)
    # 1 - tau*(1 - a)/dt, written with expm1 for accuracy when dt << tau
    b = 1.0 + tau_s * math.expm1(-dt_s / tau_s) / dt_s
    return a, b


class CoilLag:
    """Online first-order lag of a sampled signal (exact for linear-between-samples input).

    Parameters
    ----------
    time_constant_s : float
        Lag time constant ``tau``, s (>= 0; 0 passes the input through).

    Notes
    -----
    The first sample initialises the output to the input (steady state). A sample whose stamp
    is not after the previous one is treated as ``dt = 0`` (output unchanged but the input
    remembered). Units of the input are kept (degC for temperature, degC/min for its rate).

    """

    def __init__(self, time_constant_s: float) -> None:
        tau = float(time_constant_s)
        if not (math.isfinite(tau) and tau >= 0.0):
            raise ValueError(f'coil_lag_s must be a finite number >= 0 s, got {time_constant_s!r}')
        self.time_constant_s = tau
        self.reset()

    def reset(self) -> None:
        """Forget the history; the next sample starts in steady state."""
        self._stamp = math.nan
        self._x = math.nan
        self._y = math.nan

    @property
    def value(self) -> float:
        """Current output (NaN before the first sample), unit of the input."""
        return self._y

    def update(self, stamp_s: float, value: float) -> float:
        """Feed one sample (stamp in s, value in any unit); return the lagged value."""
        tau = self.time_constant_s
        if tau == 0.0 or math.isnan(self._y):
            y = value
        else:
            dt = stamp_s - self._stamp
            if dt > 0.0:
                a, b = foh_lag_coefficients(dt, tau)
                y = a * self._y + (1.0 - a) * self._x + b * (value - self._x)
            else:
                y = self._y
        self._stamp, self._x, self._y = stamp_s, value, y
        return y

    def update_block(self, stamps_s: ArrayLike, values: ArrayLike) -> FloatArray:
        """Feed samples shape (n,) in order; same result as :meth:`update` on each one."""
        t = np.asarray(stamps_s, dtype=np.float64).tolist()
        x = np.asarray(values, dtype=np.float64).tolist()
        if len(t) != len(x):
            raise ValueError(f'stamps and values must have equal length, got {len(t)}, {len(x)}')
        return np.array([self.update(ti, xi) for ti, xi in zip(t, x, strict=True)], dtype=float)


def first_order_recursion(a1: float, u: ArrayLike) -> FloatArray:
    """``y[k] = a1 * y[k-1] + u[k]`` with ``y[-1] = 0``, shape (n,), in numpy.

    A doubling scan (``y[s:] += a1**s * y[:-s]`` for ``s = 1, 2, 4, ...``): about
    ``log2(n)`` vector operations instead of a Python loop per sample, and no scipy.signal
    import (~0.7 s). Equals ``scipy.signal.lfilter([1], [1, -a1], u)`` to rounding (the sums
    are taken in another order: a few ulps of ``max|y|`` per doubling, tested).
    """
    y = np.array(u, dtype=np.float64)
    if y.ndim != 1:
        raise ValueError(f'u must be 1-D, got shape {y.shape}')
    power, shift = float(a1), 1
    while shift < y.size and power != 0.0:
        y[shift:] += power * y[:-shift]
        power *= power
        shift *= 2
    return y


def affine_scan(c: FloatArray, u: FloatArray) -> FloatArray:
    """``y[k] = c[k] * y[k-1] + u[k]`` with ``y[-1] = 0``, each shape (n,), in numpy.

    The time-varying :func:`first_order_recursion`: a doubling scan of ``log2(n)`` vector
    operations; equals the Python loop to rounding (the sums are taken in another order).
    """
    y, c = np.array(u, dtype=np.float64), np.array(c, dtype=np.float64)
    if not (y.ndim == 1 and c.shape == y.shape):
        raise ValueError(f'c and u must be 1-D of equal length, got {c.shape}, {y.shape}')
    shift = 1
    while shift < y.size:
        y[shift:] += c[shift:] * y[:-shift]
        c[shift:] *= c[:-shift]
        shift *= 2
    return y


def first_order_lfilter(b0: float, b1: float, a1: float, x: FloatArray, z0: float) -> FloatArray:
    """``scipy.signal.lfilter([b0, b1], [1, -a1], x, zi=[z0])[0]`` to rounding, without scipy.

    Parameters
    ----------
    b0, b1, a1 : float
        Numerator ``[b0, b1]`` and pole ``a1`` (denominator ``[1, -a1]``), ``|a1| < 1``.
    x : ndarray, shape (n,)
        Input.
    z0 : float
        Initial state of lfilter's transposed direct form II.

    Returns
    -------
    ndarray, shape (n,)
        Filtered ``x``.

    """
    x = np.asarray(x, dtype=np.float64)
    u = b0 * x
    u[1:] += b1 * x[:-1]
    if u.size:
        u[0] += z0
    return first_order_recursion(a1, u)


def coil_lag(stamps_s: ArrayLike, values: ArrayLike, time_constant_s: float) -> FloatArray:
    """Offline version of :class:`CoilLag` over a whole record.

    Filters with :func:`first_order_lfilter` (lfilter's result to rounding, in a few vector
    operations) when the stamps are uniform to 1e-5 relative
    (the jitter of epoch stamps in float64 at several Hz is about 1e-6) and the online
    recursion otherwise.
    On exactly uniform stamps the two agree to rounding (about 1e-12 relative); with the jitter
    allowed, to about the jitter times the step over the time constant. Other stamps (a
    driver's receive-time jitter, gaps) take each interval's exact step, in the vector
    operations of :func:`affine_scan` (the online recursion to rounding).

    Parameters
    ----------
    stamps_s : array_like, shape (n,)
        Increasing stamps, s.
    values : array_like, shape (n,)
        Signal (degC or degC/min).
    time_constant_s : float
        Lag time constant, s (>= 0).

    Returns
    -------
    ndarray, shape (n,)
        Lagged signal, unit of ``values``.

    """
    t = np.asarray(stamps_s, dtype=np.float64)
    x = np.asarray(values, dtype=np.float64)
    if t.shape != x.shape or t.ndim != 1:
        raise ValueError(
            f'stamps and values must be 1-D of equal length, got {t.shape}, {x.shape}'
        )
    tau = float(time_constant_s)
    if tau == 0.0 or x.size < 2:
        CoilLag(tau)  # validates tau
        return x.copy()
    dt = np.diff(t)
    step = float(np.median(dt))
    if step > 0 and np.all(np.abs(dt - step) <= 1e-5 * step):
        if not (math.isfinite(tau) and tau > 0):
            raise ValueError(f'coil_lag_s must be a finite number >= 0 s, got {tau!r}')
        a, b = foh_lag_coefficients(step, tau)
        # y[k] = a y[k-1] + b x[k] + (1 - a - b) x[k-1], y[0] = x[0]
        return first_order_lfilter(b, 1.0 - a - b, a, x, (1.0 - b) * float(x[0]))
    CoilLag(tau)  # validates tau
    return _irregular_lag(dt, x, tau)


def _irregular_lag(dt: FloatArray, x: FloatArray, tau: float) -> FloatArray:
    """:class:`CoilLag` over intervals ``dt`` shape (n-1,) and values ``x`` shape (n,).

    Each step is ``y[k] = a[k] y[k-1] + (1 - a[k]) x[k-1] + b[k] (x[k] - x[k-1])``
    (:func:`foh_lag_coefficients`); an interval <= 0 keeps the output (``a = 1``, ``u = 0``).
    """
    step = dt > 0.0
    ratio = np.where(step, dt, 1.0) / tau
    a = np.where(step, np.exp(-ratio), 1.0)
    b = np.where(step, 1.0 + np.expm1(-ratio) / ratio, 0.0)
    u = np.empty_like(x)
    u[0] = x[0]
    u[1:] = np.where(step, (1.0 - a) * x[:-1] + b * (x[1:] - x[:-1]), 0.0)
    c = np.empty_like(x)
    c[0] = 0.0
    c[1:] = a
    return affine_scan(c, u)


def search_time_constant(
    objective: Callable[[float], float],
    bounds_s: tuple[float, float] = (0.0, 1800.0),
    *,
    coarse_points: int = 16,
    tolerance_s: float = 1.0,
) -> tuple[float, list[tuple[float, float]]]:
    """Minimise ``objective(tau)`` over a time constant by a coarse scan and a bounded refine.

    The scan evaluates ``bounds_s[0]`` and ``coarse_points`` geometrically spaced values up to
    ``bounds_s[1]``; a bounded Brent search (SciPy's, in
    :func:`~fog_temp_comp.core.bounded_search.minimize_bounded`) then refines between the
    neighbours of the best scan point. So a minimum at 0 (no lag) is found exactly,
    and a curve with several local minima is not trapped by the first one.

    Parameters
    ----------
    objective : callable
        ``tau_s -> value`` to minimise (e.g. residual sum of squares, deg^2/h^2).
    bounds_s : tuple of float
        ``(low, high)`` search interval, s (``0 <= low < high``).
    coarse_points : int
        Number of scan points above ``low`` (>= 2).
    tolerance_s : float
        Absolute tolerance of the refine, s.

    Returns
    -------
    tau_s : float
        The best time constant found, s.
    evaluations : list of (float, float)
        Every ``(tau_s, value)`` evaluated, in evaluation order.

    """
    low, high = float(bounds_s[0]), float(bounds_s[1])
    if not (math.isfinite(low) and math.isfinite(high) and 0.0 <= low < high):
        raise ValueError(f'coil lag bounds must satisfy 0 <= low < high, got {bounds_s!r}')
    if coarse_points < 2:
        raise ValueError(f'coarse_points must be >= 2, got {coarse_points}')
    evaluations: list[tuple[float, float]] = []

    def f(tau: float) -> float:
        value = float(objective(tau))
        evaluations.append((tau, value))
        return value

    start = max(low, min(10.0, high / 100.0)) if low == 0.0 else low * 1.5
    grid = [low, *np.geomspace(min(start, high), high, coarse_points).tolist()]
    grid = sorted(set(grid))
    values = [f(tau) for tau in grid]
    best = int(np.argmin(values))
    lo = grid[max(best - 1, 0)]
    hi = grid[min(best + 1, len(grid) - 1)]
    if hi > lo:
        tau, value, _ = minimize_bounded(f, lo, hi, xatol=tolerance_s)
        if value < values[best]:
            return tau, evaluations
    return grid[best], evaluations
