"""The simulator's noise processes and its temperature sensor's quantizer (numpy, scipy.signal).

:func:`quantize` (even or uneven steps), :func:`correlated` (an AR(1) of the same std) and
:func:`gauss_markov` (the gyro's bias instability), used by
:func:`~fog_temp_comp.tools.simulate.simulate_run`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy import signal

FloatArray = NDArray[np.float64]

__all__ = ['correlated', 'gauss_markov', 'quantize']

#: the fixed pattern of :func:`quantize`'s boundary displacements (uniform in -0.5..0.5)
_DNL_PATTERN = np.random.default_rng(20261125).uniform(-0.5, 0.5, 4096)


def quantize(values: FloatArray, quantum: float, nonlinearity: float) -> FloatArray:
    """Readings of ``values`` in steps of ``quantum``, boundaries displaced by ``nonlinearity``.

    The boundary above code ``k`` sits at ``(k + 0.5 + nonlinearity * d_k) * quantum``, with
    ``d_k`` a fixed pattern uniform in -0.5..0.5 (code ``k`` modulo 4096).
    """
    code = np.round(values / quantum)
    if nonlinearity > 0:

        def boundary(k: FloatArray) -> FloatArray:
            d = _DNL_PATTERN[np.mod(k, _DNL_PATTERN.size).astype(np.intp)]
            return (k + 0.5 + nonlinearity * d) * quantum

        code = code + (values >= boundary(code)) - (values < boundary(code - 1.0))
    return code * quantum


def correlated(white: FloatArray, a: float) -> FloatArray:
    """AR(1) of coefficient ``a`` driven by ``white``, with the same std (stationary start)."""
    b = np.sqrt(1.0 - a * a)
    return signal.lfilter([b], [1.0, -a], white, zi=[(1.0 - b) * white[0]])[0]


def gauss_markov(
    rng: np.random.Generator, n: int, dt_s: float, sigma: float, tau_s: float
) -> FloatArray:
    """First-order Gauss-Markov process, shape (n, 3), stationary std ``sigma``."""
    if sigma <= 0 or n == 0:
        return np.zeros((n, 3))
    phi = np.exp(-dt_s / tau_s)
    drive = rng.normal(0.0, sigma * np.sqrt(1 - phi**2), size=(n, 3))
    drive[0] = rng.normal(0.0, sigma, size=3)
    out, _ = signal.lfilter([1.0], [1.0, -phi], drive, axis=0, zi=np.zeros((1, 3)))
    return out
