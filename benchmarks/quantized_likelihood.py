"""Side study: Kalman filters with the exact likelihood of a quantized reading (not in package).

Run by hand (not in CI)::

    .venv/bin/python benchmarks/quantized_likelihood.py                   # Tdot errors, 5 plants
    .venv/bin/python benchmarks/quantized_likelihood.py --plants 904 102
    .venv/bin/python benchmarks/quantized_likelihood.py --accuracy [accuracy.py options]

The package's Kalman filters take a reading ``y`` for ``T + v``, ``v`` white of variance
``noise^2 + quantum^2 / 12``. For a quiet sensor (noise well under a step) that is wrong where
the temperature hovers at a step boundary: the readings toggle, and their mean sweeps across a
step while the temperature barely moves (README, "Readings that toggle between two steps").
Here a reading at level ``y`` means ``y - q/2 <= T + e < y + q/2`` with ``e ~ N(0, sigma^2)``,
and each filter step matches the moments of the Gaussian prior times that likelihood
(assumed-density filtering). For ``z = h'x ~ N(m, s2)``, ``w = z + e`` truncated to the
reading's interval, with ``v = s2 + sigma^2``::

    E[z|y] = m + (s2 / v) (E[w|y] - m),   Var[z|y] = s2 - s2^2 / v + (s2 / v)^2 Var[w|y]
    x += P h (E[z|y] - m) / s2,           P -= P h h'P (s2 - Var[z|y]) / s2^2

with the truncated normal's moments computed stably (erfcx in the tails). Raw readings are
used one at a time (no 0.5 s averaging); a held reading is damped by the package's repeat
factor (:mod:`fog_temp_comp.core.reading_repeat`). ``sigma`` is fitted by maximum likelihood
(the filter's own predictive log-likelihood over the training run, on a grid of 0.02-0.56
quanta, refined by a parabola in log sigma): ``calibrate``'s moment estimate is 0 for a sensor
quieter than about 0.15 quantum, and the filter needs sigma within about +-30 % (1.4x too large
gave plant 102 a limit cycle on its soaks).

Default mode: per plant (seed 0), the coil-Tdot RMS error and the std of its 100 s means after
the first 30 min on four runs, for the package's sensor-lag filter (the plant's true lag, the
noise ``calibrate`` measures) and this one (the same lag and walk, sigma fitted). ``--accuracy``:
``benchmarks/accuracy.py`` with both package filters replaced by these (sigma fitted on each
plant's training run; the filter counts as warmed up 300 s after its first reading);
``--quantized-cap`` damps updates less than 1 s apart, ``--quantized-thin-s S`` uses only
readings at least ``S`` s after the last one used (the speed of a 10 Hz sensor), and
``--quantized-hybrid`` cross-validates with the package's filters and uses these for the final
fit and the replays only (about 12 filter runs fewer than 40 in calibration).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Sequence

import numpy as np

from fog_temp_comp.core.denoise import DenoiseSettings
from fog_temp_comp.core.reading_repeat import RepeatedReadings
from fog_temp_comp.core.sensor_noise import sensor_noise
from fog_temp_comp.core.tdot import kalman_estimator
from fog_temp_comp.core.tdot_kalman_lag import sensor_lag_transition

SQRT2 = math.sqrt(2.0)
INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)
#: sigma grid of the likelihood fit, quanta
SIGMA_GRID_QUANTA = (0.02, 0.03, 0.04, 0.05, 0.07, 0.1, 0.14, 0.2, 0.28, 0.4, 0.56)
RUNS = ('cycle_0p2', 'cycle_1', 'soak_m40', 'soak_30')


def erfcx(x: float) -> float:
    """``exp(x^2) erfc(x)`` for ``x >= 0``."""
    if x < 25.0:
        return math.exp(x * x) * math.erfc(x)
    x2 = 1.0 / (x * x)
    return (1.0 - 0.5 * x2 + 0.75 * x2 * x2 - 1.875 * x2**3) / (x * math.sqrt(math.pi))


def truncated_moments(a: float, b: float) -> tuple[float, float, float]:
    """Mean, variance and log mass of a standard normal truncated to ``[a, b]`` (a < b)."""
    flip = a > 0.0
    if flip:
        a, b = -b, -a
    if b >= 0.0:  # the interval holds 0: its mass is not small
        mass = 0.5 * (math.erf(b / SQRT2) - math.erf(a / SQRT2))
        pa = INV_SQRT_2PI * math.exp(-0.5 * a * a) if a > -40.0 else 0.0
        pb = INV_SQRT_2PI * math.exp(-0.5 * b * b) if b < 40.0 else 0.0
        mean = (pa - pb) / mass
        var = 1.0 + ((a * pa if pa else 0.0) - (b * pb if pb else 0.0)) / mass - mean * mean
        log_mass = math.log(mass) if mass > 0.0 else -745.0
    else:  # both bounds in the lower tail: mirror to [c, d], c > 0, and use erfcx
        c, d = -b, -a
        e = 0.0 if d == math.inf else math.exp(0.5 * (c - d) * (c + d))
        scaled = 0.5 * (erfcx(c / SQRT2) - (e * erfcx(d / SQRT2) if e else 0.0))
        log_mass = math.log(scaled) - 0.5 * c * c if scaled > 0.0 else -745.0
        rc = INV_SQRT_2PI / scaled  # phi(c) / mass
        rd = e * rc
        mean = -(rc - rd)
        var = 1.0 + (c * rc - (d * rd if rd else 0.0)) - (rc - rd) ** 2
    return (-mean if flip else mean), max(var, 1e-12), log_mass


class QuantizedKalman:
    """Sensor-lag (``tau_s > 0``: coil T, coil Tdot, sensor T) or plain (T, Tdot) filter.

    ``step`` takes one raw reading (degC) at a stamp (s); ``x[1]`` is Tdot in degC/s. With
    ``cap`` an update ``dt`` < 1 s after the last is damped by ``dt`` (first-order tempering:
    at most one reading's information per second), which keeps the filter stable where sigma
    is off by 0.7x-2x, at some cost on ramps.
    """

    def __init__(
        self,
        quantum: float,
        sigma: float,
        tau_s: float,
        walk: float,
        repeat: float,
        cap: bool = False,
    ):
        self.q, self.sig2, self.tau, self.cap = quantum, sigma * sigma, tau_s, cap
        self.qw = (walk / 60.0) ** 2
        self.repeat = RepeatedReadings(quantum, repeat)
        self.cache: dict[float, tuple] = {}
        self.log_likelihood = 0.0
        self.last = math.nan
        self.x: list[float] = []
        self.p: list[float] = []

    def start(self, t: float, y: float) -> None:
        """First reading ``y`` (degC) at ``t`` (s): the prior, as the package's filters."""
        r0, v0 = self.sig2 + self.q * self.q / 12.0, (1.0 / 60.0) ** 2
        self.last = t
        self.repeat.factor(t, y)
        if self.tau > 0.0:
            self.x = [y, 0.0, y]
            self.p = [r0 + self.tau**2 * v0, self.tau * v0, r0, v0, 0.0, r0]
        else:
            self.x, self.p = [y, 0.0], [r0, 0.0, v0]

    def _update(self, m: float, s2: float, y: float) -> tuple[float, float]:
        """Posterior mean and variance of the measured state given reading ``y``."""
        v = s2 + self.sig2
        sv = math.sqrt(v)
        mw, vw, log_mass = truncated_moments(
            (y - 0.5 * self.q - m) / sv, (y + 0.5 * self.q - m) / sv
        )
        self.log_likelihood += log_mass
        k = s2 / v
        return m + k * sv * mw, s2 - s2 * k + k * k * v * vw

    def step(self, t: float, y: float) -> bool:
        """Predict to ``t`` (s) and update with reading ``y`` (degC); False if not after."""
        dt = round((t - self.last) * 1e5) / 1e5
        if not dt > 0.0:
            return False
        damp = 1.0 / self.repeat.factor(t, y)
        if self.cap and dt < 1.0:  # readings less than 1 s apart count as one
            damp *= dt
        if self.tau > 0.0:
            self._step_lag(dt, y, damp)
        else:
            self._step_plain(dt, y, damp)
        self.last = t
        return True

    def _step_lag(self, dt: float, y: float, damp: float) -> None:
        tr = self.cache.get(dt)
        if tr is None:
            tr = self.cache[dt] = sensor_lag_transition(dt, self.tau, self.qw)
        (a, b, c), (q_cc, q_cv, q_cs, q_vv, q_vs, q_ss) = tr
        cc, cv, cs, vv, vs, ss = self.p
        tc, v, ts = self.x
        f_c, f_v, f_s = (
            b * cc + c * cv + a * cs,
            b * cv + c * vv + a * vs,
            b * cs + c * vs + a * ss,
        )
        cc, cv = cc + 2.0 * dt * cv + dt * dt * vv + q_cc, cv + dt * vv + q_cv
        cs, vv, vs = f_c + dt * f_v + q_cs, vv + q_vv, f_v + q_vs
        ss = b * f_c + c * f_v + a * f_s + q_ss
        tc, ts = tc + dt * v, a * ts + b * tc + c * v
        ez, vz = self._update(ts, ss, y)
        g, h = damp * (ez - ts) / ss, damp * (ss - vz) / (ss * ss)
        self.x = [tc + cs * g, v + vs * g, ts + ss * g]
        self.p = [
            cc - cs * cs * h,
            cv - cs * vs * h,
            cs - cs * ss * h,
            vv - vs * vs * h,
            vs - vs * ss * h,
            ss - ss * ss * h,
        ]

    def _step_plain(self, dt: float, y: float, damp: float) -> None:
        p00, p01, p11 = self.p
        qw = self.qw
        p00 = p00 + 2.0 * dt * p01 + dt * dt * p11 + qw * dt**3 / 3.0
        p01, p11 = p01 + dt * p11 + qw * dt * dt / 2.0, p11 + qw * dt
        x0 = self.x[0] + dt * self.x[1]
        ez, vz = self._update(x0, p00, y)
        g, h = damp * (ez - x0) / p00, damp * (p00 - vz) / (p00 * p00)
        self.x = [x0 + p00 * g, self.x[1] + p01 * g]
        self.p = [p00 - p00 * p00 * h, p01 - p00 * p01 * h, p11 - p01 * p01 * h]

    @property
    def tdot_std_degC_per_min(self) -> float:
        """Posterior standard deviation of Tdot, degC/min."""
        return math.sqrt(max(self.p[3] if self.tau > 0.0 else self.p[2], 0.0)) * 60.0


def run(filt: QuantizedKalman, t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Stamps (s) and Tdot (degC/min) of ``filt`` over readings ``y`` at ``t``."""
    tl, yl = t.tolist(), y.tolist()
    filt.start(tl[0], yl[0])
    out_t, out_v = [tl[0]], [0.0]
    for tk, yk in zip(tl[1:], yl[1:], strict=True):
        if filt.step(tk, yk):
            out_t.append(tk)
            out_v.append(filt.x[1] * 60.0)
    return np.asarray(out_t), np.asarray(out_v)


def fit_sigma(t: np.ndarray, y: np.ndarray, quantum: float, walk: float = 0.001) -> float:
    """Sigma (degC) of the largest likelihood of the plain filter over readings ``y``."""
    ll = []
    for c in SIGMA_GRID_QUANTA:
        filt = QuantizedKalman(quantum, c * quantum, 0.0, walk, 0.0)
        run(filt, t, y)
        ll.append(filt.log_likelihood)
    i = int(np.argmax(ll))
    c = SIGMA_GRID_QUANTA[i]
    if 0 < i < len(ll) - 1:
        x = np.log(SIGMA_GRID_QUANTA[i - 1 : i + 2])
        p = np.polyfit(x, ll[i - 1 : i + 2], 2)
        c = float(np.exp(-p[1] / (2.0 * p[0])))
    return c * quantum


def score(stamps: np.ndarray, tdot: np.ndarray, truth_t: np.ndarray, truth: np.ndarray):
    """RMS error and std of 100 s means of the error after 30 min, degC/min."""
    err = tdot - np.interp(stamps, truth_t, truth)
    keep = stamps > stamps[0] + 1800.0
    err, ts = err[keep], stamps[keep]
    k = ((ts - ts[0]) // 100.0).astype(int)
    means = np.bincount(k, err) / np.bincount(k)
    return float(np.sqrt(np.mean(err**2))), float(means.std())


def compare_plant(plant: int) -> list[str]:
    """Table rows of one plant: the package's filter against this one."""
    from fog_temp_comp.tools.plants import draw_plant
    from fog_temp_comp.tools.simulate import simulate_plan

    cfg = draw_plant(plant)
    runs = simulate_plan(cfg, seed=0)
    train = runs['cycle_0p2']
    q, lag = cfg.temp_quantum_degC, cfg.sensor_lag_s
    noise = sensor_noise([train.as_record()]).noise_degC
    sigma = fit_sigma(train.temp_stamps_s, train.temperature_degC, q)
    rows = [f'| {plant} | {cfg.temp_noise_degC / q:.2f} | {noise:.4f} | {sigma:.4f} |']
    for name in RUNS:
        r = runs[name]
        settings = DenoiseSettings(
            method='kalman',
            kalman_rate_walk_degC_per_min_per_sqrt_s=0.001,
            temperature_noise_degC=noise,
            temperature_quantum_degC=q,
            sensor_lag_s=lag,
            kalman_repeat_rate_degC_per_min=0.1,
        )
        e = kalman_estimator(settings).add_series(r.temp_stamps_s, r.temperature_degC)
        now = score(e.stamp_s, e.tdot_degC_per_min, r.imu_stamps_s, r.true_tdot_degC_per_min)
        st, td = run(
            QuantizedKalman(q, sigma, lag, 0.001, 0.1), r.temp_stamps_s, r.temperature_degC
        )
        new = score(st, td, r.imu_stamps_s, r.true_tdot_degC_per_min)
        rows[0] += f' {now[0]:.4f} ({now[1]:.4f}) / {new[0]:.4f} ({new[1]:.4f}) |'
    return rows


def main(argv: Sequence[str] | None = None) -> int:
    """Print the comparison table, or run the accuracy study with these filters."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ['--accuracy']:
        import quantized_patch  # the package's filters replaced (this directory)

        return quantized_patch.accuracy_main(argv[1:])
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--plants', type=int, nargs='+', default=[102, 904, 907, 905, 100])
    args = parser.parse_args(argv)
    print(
        '| plant | true noise / quantum | noise measured, degC | sigma fitted, degC | '
        + ' | '.join(f'{n}: Tdot RMS (100 s std), package / quantized' for n in RUNS)
        + ' |'
    )
    print('|' + '---|' * (4 + len(RUNS)))
    for plant in args.plants:
        for row in compare_plant(plant):
            print(row, flush=True)
    return 0


if __name__ == '__main__':
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    raise SystemExit(main())
