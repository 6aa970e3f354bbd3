"""Causal Butterworth low-pass filtering of Tdot (method ``'iir'``), offline and online.

:func:`butterworth_filter` filters a whole record, :class:`ButterworthDenoiser` one sample at a
time, with identical results.  Periods are in seconds, frequencies in Hz, Tdot in degC/min.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fog_temp_comp.core.denoise_options import _as_finite_1d, _as_finite_scalar, _check_butter

__all__ = ['ButterworthDenoiser', 'butterworth_filter']


def _butter_sos(order: int, cutoff_hz: float, sample_period_s: float) -> NDArray[np.float64]:
    from scipy import signal

    sos = signal.butter(order, cutoff_hz, btype='low', output='sos', fs=1.0 / sample_period_s)
    return np.asarray(sos, dtype=np.float64)


def butterworth_filter(
    x: ArrayLike, *, order: int, cutoff_hz: float, sample_period_s: float
) -> NDArray[np.float64]:
    """Causally low-pass filter a whole record with a Butterworth filter.

    Same result as :class:`ButterworthDenoiser` fed sample by sample: the filter state is
    initialised to the steady state for the first sample (``sosfilt_zi(sos) * x[0]``), so a
    constant input produces a constant output without a start-up transient.

    Parameters
    ----------
    x : array_like, shape (n,)
        Signal sampled every ``sample_period_s`` seconds (e.g. Tdot, degC/min).
    order : int
        Filter order (>= 1).
    cutoff_hz : float
        -3 dB cut-off frequency, Hz (``0 < cutoff_hz < 0.5 / sample_period_s``).
    sample_period_s : float
        Sample period, s (> 0).

    Returns
    -------
    numpy.ndarray, shape (n,), float64
        Filtered signal, same units as ``x``.

    """
    order_i, cutoff, period = _check_butter(order, cutoff_hz, sample_period_s)
    arr = _as_finite_1d(x)
    if arr.size == 0:
        return arr
    sos = _butter_sos(order_i, cutoff, period)
    from scipy import signal

    y, _ = signal.sosfilt(sos, arr, zi=signal.sosfilt_zi(sos) * arr[0])
    return np.asarray(y, dtype=np.float64)


class ButterworthDenoiser:
    """Online causal Butterworth low-pass filter (method ``'iir'``).

    Parameters
    ----------
    order : int
        Filter order (>= 1).
    cutoff_hz : float
        -3 dB cut-off frequency, Hz (``0 < cutoff_hz < 0.5 / sample_period_s``).
    sample_period_s : float
        Tdot sample period, s (> 0).

    Notes
    -----
    The second-order-section state is carried between calls as ``sosfilt(..., zi=...)``
    does, with the same arithmetic (tested against ``sosfilt``).  On the first sample the state
    is set to the steady state for that sample, so :attr:`ready` is true from the first sample
    on.

    """

    def __init__(self, order: int, cutoff_hz: float, sample_period_s: float) -> None:
        self.order, self.cutoff_hz, self.sample_period_s = _check_butter(
            order, cutoff_hz, sample_period_s
        )
        self.sos = _butter_sos(self.order, self.cutoff_hz, self.sample_period_s)
        # per section (b0, b1, b2, a1, a2) and steady-state state per unit input, as floats:
        # one sample at a time, a Python loop beats a sosfilt call (and allocates nothing)
        self._sections = [(b0, b1, b2, a1, a2) for b0, b1, b2, _, a1, a2 in self.sos.tolist()]
        from scipy import signal

        self._zi_unit = np.asarray(signal.sosfilt_zi(self.sos), dtype=np.float64).tolist()
        self._zi: list[list[float]] | None = None
        self._count = 0

    def _step(self, x: float) -> float:
        """One sample through the cascade: ``sosfilt``'s transposed direct form II."""
        zi = self._zi
        if zi is None:
            zi = self._zi = [[z0 * x, z1 * x] for z0, z1 in self._zi_unit]
        for (b0, b1, b2, a1, a2), state in zip(self._sections, zi, strict=True):
            y = b0 * x + state[0]
            state[0] = b1 * x - a1 * y + state[1]
            state[1] = b2 * x - a2 * y
            x = y
        self._count += 1
        return x

    def update(self, tdot_degC_per_min: float) -> float:
        """Filter one raw Tdot sample (degC/min); return the filtered value (degC/min)."""
        return self._step(_as_finite_scalar(tdot_degC_per_min))

    def update_block(self, values: ArrayLike) -> NDArray[np.float64]:
        """Filter samples shape (n,) in order (degC/min); same as repeated :meth:`update`."""
        arr = _as_finite_1d(values, 'values')
        return np.array([self._step(v) for v in arr.tolist()], dtype=np.float64)

    def reset(self) -> None:
        """Forget the filter state; the next sample re-initialises it."""
        self._zi = None
        self._count = 0

    @property
    def ready(self) -> bool:
        """``True`` once the first sample has initialised the filter state."""
        return self._zi is not None

    @property
    def samples_seen(self) -> int:
        """Number of samples fed since construction or the last reset."""
        return self._count
