"""Brent's bounded minimisation of a scalar function, without importing scipy.optimize.

``calibrate`` refines a time constant (a coil, sensor or lead-lag lag) by a bounded Brent
search on its cross-validated score, which was ``scipy.optimize.minimize_scalar(method=
'bounded')``. Importing ``scipy.optimize`` takes about 0.5 s, which since session 27 nearly
every default ``calibrate`` paid (the quantized-likelihood step scores and refines rival
dynamics): a sixth of a 6.75 h, 50 Hz run's calibration (``benchmarks/bench_compensate.py``).
:func:`minimize_bounded` is SciPy's ``_minimize_scalar_bounded`` (scipy 1.17,
``scipy/optimize/_optimize.py``; BSD-3-Clause, Copyright (c) 2001-2002 Enthought, Inc. and
2003-2024 SciPy Developers), the same operations in the same order on Python floats, so it
evaluates the function at the same points to the last bit (tested against SciPy).
"""

from __future__ import annotations

import math
from collections.abc import Callable

__all__ = ['minimize_bounded']

_SQRT_EPS = math.sqrt(2.2e-16)
_GOLDEN_MEAN = 0.5 * (3.0 - math.sqrt(5.0))


def _sign_or_one(value: float) -> float:
    """``np.sign(value) + (value == 0)``: -1.0 below zero, else 1.0 (NaN stays NaN)."""
    if math.isnan(value):
        return value
    return -1.0 if value < 0.0 else 1.0


def minimize_bounded(
    func: Callable[[float], float],
    low: float,
    high: float,
    *,
    xatol: float = 1e-5,
    maxiter: int = 500,
) -> tuple[float, float, int]:
    """Minimise ``func`` on ``[low, high]``: the best point, its value, the evaluations made.

    Golden-section steps with parabolic interpolation, to ``xatol`` in x or ``maxiter``
    evaluations, as ``scipy.optimize.minimize_scalar(func, bounds=(low, high),
    method='bounded', options={'xatol': xatol, 'maxiter': maxiter})``.
    """
    if not (math.isfinite(low) and math.isfinite(high)):
        raise ValueError('bounds must be finite')
    if low > high:
        raise ValueError(f'the lower bound {low} exceeds the upper bound {high}')
    a, b = float(low), float(high)
    fulc = a + _GOLDEN_MEAN * (b - a)
    nfc = xf = fulc
    rat = e = 0.0
    fx = func(xf)
    num = 1
    ffulc = fnfc = fx
    xm = 0.5 * (a + b)
    tol1 = _SQRT_EPS * abs(xf) + xatol / 3.0
    tol2 = 2.0 * tol1
    while abs(xf - xm) > (tol2 - 0.5 * (b - a)):
        golden = True
        if abs(e) > tol1:  # try a parabolic fit
            golden = False
            r = (xf - nfc) * (fx - ffulc)
            q = (xf - fulc) * (fx - fnfc)
            p = (xf - fulc) * q - (xf - nfc) * r
            q = 2.0 * (q - r)
            if q > 0.0:
                p = -p
            q = abs(q)
            r = e
            e = rat
            if abs(p) < abs(0.5 * q * r) and p > q * (a - xf) and p < q * (b - xf):
                rat = (p + 0.0) / q
                x = xf + rat
                if (x - a) < tol2 or (b - x) < tol2:
                    rat = tol1 * _sign_or_one(xm - xf)
            else:
                golden = True
        if golden:  # a golden-section step
            e = a - xf if xf >= xm else b - xf
            rat = _GOLDEN_MEAN * e
        step = abs(rat)
        x = xf + _sign_or_one(rat) * (step if math.isnan(step) else max(step, tol1))
        fu = func(x)
        num += 1
        if fu <= fx:
            if x >= xf:
                a = xf
            else:
                b = xf
            fulc, ffulc = nfc, fnfc
            nfc, fnfc = xf, fx
            xf, fx = x, fu
        else:
            if x < xf:
                a = x
            else:
                b = x
            if fu <= fnfc or nfc == xf:
                fulc, ffulc = nfc, fnfc
                nfc, fnfc = x, fu
            # == as SciPy's (``in`` would also match a NaN by identity)
            elif fu <= ffulc or fulc == xf or fulc == nfc:  # noqa: SIM109
                fulc, ffulc = x, fu
        xm = 0.5 * (a + b)
        tol1 = _SQRT_EPS * abs(xf) + xatol / 3.0
        tol2 = 2.0 * tol1
        if num >= maxiter:
            break
    return xf, fx, num
