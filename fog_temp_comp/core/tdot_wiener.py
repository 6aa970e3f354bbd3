"""The Wiener gain on Tdot: keep the share of its recent power that is not estimator noise.

At constant temperature the Kalman Tdot is mostly the filter's own noise, and the drift model
multiplies it by DTdot (and, where the sensor sits behind the coil, by the fitted lead, which
amplifies it): the soak's corrected output gets noisier than the raw one. On a ramp, or where
the chamber's wobble is large enough for the sensor to resolve, Tdot is mostly signal. The
gain tells them apart by the power of the recent estimates against the estimator's posterior
variance ``sigma^2``::

    m2[k]  = m2[k-1] + a[k] * (tdot[k]^2 - m2[k-1]),   a[k] = 1 - exp(-dt[k] / window_s)
    gain[k] = max(0, 1 - sigma[k]^2 / m2[k])

``m2`` is the exponentially weighted mean square of Tdot over about ``window_s`` seconds, so
``m2 - sigma^2`` estimates the signal's power and the gain is the Wiener filter's
``signal / (signal + noise)``: near 1 on a ramp of more than a few sigma, near 0 on a soak the
sensor cannot resolve. Tdot in degC/min, stamps and the window in s.

:class:`WienerGain` runs online, once per estimate; :func:`wiener_gains` gives the same gains
(to rounding) over a whole series in ``log2(n)`` vector operations.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fog_temp_comp.core.coil import affine_scan

FloatArray = NDArray[np.float64]

__all__ = ['WienerGain', 'wiener_gains']


def _check_window(window_s: float) -> float:
    window = float(window_s)
    if not (math.isfinite(window) and window >= 0.0):
        raise ValueError(f'tdot_wiener_window_s must be a finite number >= 0 s, got {window_s!r}')
    return window


class WienerGain:
    """Online Wiener gain of a Tdot stream (see the module docstring).

    Parameters
    ----------
    window_s : float
        Time constant of the mean square, s (0: the gain is always 1).

    Notes
    -----
    A stamp not after the previous one leaves the mean square as it is. An estimate without a
    posterior standard deviation (NaN) gets gain 1.

    """

    def __init__(self, window_s: float) -> None:
        self.window_s = _check_window(window_s)
        self.reset()

    def reset(self) -> None:
        """Forget the history."""
        self._stamp = math.nan
        self._m2 = math.nan

    def update(self, stamp_s: float, tdot_degC_per_min: float, std_degC_per_min: float) -> float:
        """Feed one estimate; return its gain in [0, 1]."""
        if self.window_s == 0.0 or math.isnan(std_degC_per_min):
            return 1.0
        x2 = tdot_degC_per_min * tdot_degC_per_min
        if math.isnan(self._m2):
            self._m2, self._stamp = x2, stamp_s
        elif stamp_s > self._stamp:
            self._m2 += -math.expm1((self._stamp - stamp_s) / self.window_s) * (x2 - self._m2)
            self._stamp = stamp_s
        if not self._m2 > 0.0:
            return 0.0
        return max(0.0, 1.0 - std_degC_per_min * std_degC_per_min / self._m2)


def wiener_gains(
    stamps_s: ArrayLike, tdot_degC_per_min: ArrayLike, std_degC_per_min: ArrayLike, window_s: float
) -> FloatArray:
    """Gains of :class:`WienerGain` over a whole series, each shape (n,), to rounding.

    Parameters
    ----------
    stamps_s : array_like, shape (n,)
        Non-decreasing stamps, s.
    tdot_degC_per_min, std_degC_per_min : array_like, shape (n,)
        Tdot and its posterior standard deviation (NaN: unknown, gain 1), degC/min.
    window_s : float
        Time constant of the mean square, s (0: all gains 1).

    Returns
    -------
    ndarray, shape (n,)
        Gains in [0, 1].

    """
    window = _check_window(window_s)
    t = np.asarray(stamps_s, dtype=np.float64)
    x = np.asarray(tdot_degC_per_min, dtype=np.float64)
    std = np.asarray(std_degC_per_min, dtype=np.float64)
    if not (t.shape == x.shape == std.shape and t.ndim == 1):
        raise ValueError(
            f'stamps, Tdot and std must be 1-D of equal length, got {t.shape}, {x.shape}, '
            f'{std.shape}'
        )
    known = ~np.isnan(std)
    gains = np.ones_like(x)
    if window == 0.0 or not np.any(known):
        return gains
    # the online filter sees only the estimates with a standard deviation
    tk, x2, s2 = t[known], x[known] ** 2, std[known] ** 2
    a = np.zeros_like(x2)
    a[1:] = -np.expm1(-np.diff(np.maximum.accumulate(tk)) / window)
    u = a * x2
    u[0] = x2[0]
    m2 = affine_scan(1.0 - a, u)
    with np.errstate(divide='ignore', invalid='ignore'):
        gain = np.where(m2 > 0.0, np.maximum(0.0, 1.0 - s2 / m2), 0.0)
    gains[known] = gain
    return gains
