"""Overlapping Allan deviation of a gyro rate record (deg/h against averaging time in s).

Computed by ``allantools.oadev`` (IEEE Std 952 / NIST SP 1065, octave taus), imported only
when a deviation is computed; used by the calibration report's plots and tables.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: IEEE Std 952 Annex C: bias instability = minimum of the Allan deviation / 0.664 (flicker)
BIAS_INSTABILITY_FACTOR = 0.664
#: fewest samples for which an Allan deviation is computed
MIN_ALLAN_SAMPLES = 16


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
