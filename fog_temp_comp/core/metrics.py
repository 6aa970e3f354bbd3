"""Bias stability and range of a gyro record (GJB2426A style, as in the paper's Tables 2 and 3)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


def window_means(stamps_s: ArrayLike, values: ArrayLike, window_s: float) -> FloatArray:
    """Means of consecutive non-overlapping windows of ``window_s`` seconds.

    Windows start at the first stamp; empty windows are skipped, and the last window is dropped
    when it holds fewer samples than the fullest one (record ended inside it).

    Parameters
    ----------
    stamps_s : array_like, shape (N,)
        Non-decreasing stamps (s).
    values : array_like, shape (N,) or (N, M)
        Samples, any unit (the means have the same unit).
    window_s : float
        Averaging time (s).

    Returns
    -------
    ndarray, shape (K,) or (K, M)

    """
    t = np.asarray(stamps_s, dtype=np.float64)
    x = np.asarray(values, dtype=np.float64)
    if t.ndim != 1 or x.shape[:1] != t.shape:
        raise ValueError(f'stamps (N,) and values (N, ...) expected, got {t.shape}, {x.shape}')
    if not window_s > 0:
        raise ValueError(f'window_s must be > 0, got {window_s}')
    if t.size == 0:
        return np.empty((0, *x.shape[1:]))
    k = np.floor((t - t[0]) / window_s).astype(np.int64)
    starts = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
    counts = np.diff(np.r_[starts, k.size])
    sums = np.add.reduceat(x, starts, axis=0)
    if counts.size > 1 and counts[-1] < counts.max():
        sums, counts = sums[:-1], counts[:-1]
    return sums / (counts if x.ndim == 1 else counts[:, None])


def bias_stability(means: ArrayLike) -> FloatArray:
    """Std (ddof=1) of window means along axis 0, same unit as the means."""
    m = np.asarray(means, dtype=np.float64)
    if m.shape[0] < 2:
        return np.full(m.shape[1:], np.nan)
    return np.std(m, axis=0, ddof=1)


def bias_range(means: ArrayLike) -> FloatArray:
    """Max minus min of window means along axis 0, same unit as the means."""
    m = np.asarray(means, dtype=np.float64)
    if m.shape[0] < 1:
        return np.full(m.shape[1:], np.nan)
    return np.max(m, axis=0) - np.min(m, axis=0)
