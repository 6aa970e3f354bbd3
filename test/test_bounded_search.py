"""The bounded Brent search against SciPy's: the same evaluation points, to the last bit."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from scipy import optimize

from fog_temp_comp.core.bounded_search import minimize_bounded


def _noisy(x: float) -> float:
    """A cross-validated score's shape: a shallow bowl with ripples, deterministic."""
    return 0.3 + 0.01 * (x - 4.7) ** 2 + 0.002 * math.sin(37.0 * x)


def _refused_below_4(x: float) -> float:
    """A time constant refused below 4 (the penalty ``refine_time_constant`` returns)."""
    return 1e6 if x < 4.0 else (x - 4.2) ** 2


FUNCTIONS: dict[str, Callable[[float], float]] = {
    'quadratic': lambda x: (x - 1.3) ** 2,
    'noisy': _noisy,
    'refused below 4': _refused_below_4,
    'flat': lambda x: 0.5,
    'monotone': lambda x: -x,
    'abs': lambda x: abs(x - 2.0),
}


@pytest.mark.parametrize('name', list(FUNCTIONS))
@pytest.mark.parametrize(
    ('low', 'high', 'xatol', 'maxiter'),
    [
        (math.log(30.0), math.log(120.0), 0.05, 5),  # refine_time_constant's use
        (math.log(50.0), math.log(200.0), 0.05, 8),
        (math.log(60.0), math.log(240.0), 0.05, 2),
        (0.0, 10.0, 1e-5, 500),
        (-3.0, 3.0, 1e-3, 40),
        (2.0, 2.0, 1e-5, 500),  # an empty interval
    ],
)
def test_the_same_points_as_scipy(
    name: str, low: float, high: float, xatol: float, maxiter: int
) -> None:
    func = FUNCTIONS[name]
    ours: list[float] = []
    theirs: list[float] = []
    x, fun, nfev = minimize_bounded(
        lambda v: ours.append(v) or func(v), low, high, xatol=xatol, maxiter=maxiter
    )
    reference = optimize.minimize_scalar(
        lambda v: theirs.append(float(v)) or func(float(v)),
        bounds=(low, high),
        method='bounded',
        options={'xatol': xatol, 'maxiter': maxiter},
    )
    assert_array_equal(np.array(ours), np.array(theirs))
    assert x == reference.x and fun == reference.fun and nfev == reference.nfev


def test_bounds_are_checked() -> None:
    with pytest.raises(ValueError, match='exceeds'):
        minimize_bounded(abs, 2.0, 1.0)
    with pytest.raises(ValueError, match='finite'):
        minimize_bounded(abs, 0.0, math.inf)
