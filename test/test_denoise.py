"""Tests for fog_temp_comp.core.denoise (Tdot denoising)."""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest
import pywt
from numpy.testing import assert_allclose, assert_array_equal
from scipy import signal

from fog_temp_comp.core.denoise import (
    GRID_METHODS,
    METHODS,
    ButterworthDenoiser,
    DenoiseSettings,
    PassThroughDenoiser,
    SlidingWaveletDenoiser,
    TdotDenoiser,
    butterworth_filter,
    denoise_offline,
    make_denoiser,
    min_window_samples,
    select_threshold,
    wavelet_denoise,
)

RULES = ('heursure', 'rigrsure', 'sqtwolog', 'minimaxi')

# Small, fast configuration for the sliding-window tests: db4 at level 3 needs >= 56 samples.
SMALL = DenoiseSettings(wavelet='db4', wavelet_level=3, window_samples=64, delay_samples=5)


# --------------------------------------------------------------------------------------------
# Independent references (MATLAB thselect / wden, written differently from the module)
# --------------------------------------------------------------------------------------------


def ref_thselect(x: np.ndarray, rule: str) -> float:
    """Straightforward loop version of MATLAB thselect."""
    x = np.asarray(x, dtype=float)
    n = x.size
    if rule == 'sqtwolog':
        return math.sqrt(2.0 * math.log(n))
    if rule == 'minimaxi':
        return 0.0 if n <= 32 else 0.3936 + 0.1829 * (math.log(n) / math.log(2.0))
    if rule == 'rigrsure':
        # SURE(t) = n - 2 #{|x| <= t} + sum(min(x^2, t^2)), minimised over t in |x|.
        best_risk, best_t = math.inf, 0.0
        for t in np.sort(np.abs(x)):
            risk = (n - 2 * np.count_nonzero(np.abs(x) <= t) + np.minimum(x**2, t**2).sum()) / n
            if risk < best_risk:
                best_risk, best_t = risk, float(t)
        return best_t
    if rule == 'heursure':
        hthr = math.sqrt(2.0 * math.log(n))
        eta = (np.linalg.norm(x) ** 2 - n) / n
        crit = (math.log(n) / math.log(2.0)) ** 1.5 / math.sqrt(n)
        return hthr if eta < crit else min(ref_thselect(x, 'rigrsure'), hthr)
    raise AssertionError(rule)


def ref_wden(x, rule, sorh, scal, level, wname, mode='symmetric'):
    """MATLAB wden built directly from pywt primitives."""
    x = np.asarray(x, dtype=float)
    c = pywt.wavedec(x, wname, mode=mode, level=level)
    det = c[1:]
    if scal == 'one':
        s = [1.0] * level
    elif scal == 'sln':
        s = [np.median(np.abs(det[-1])) / 0.6745] * level
    else:
        s = [np.median(np.abs(d)) / 0.6745 for d in det]
    new = [c[0]]
    for d, sk in zip(det, s, strict=True):
        if rule in ('sqtwolog', 'minimaxi'):
            thr = ref_thselect(x, rule)
        elif sk < np.sqrt(np.finfo(float).eps) * np.max(np.abs(d)):
            thr = 0.0
        else:
            thr = ref_thselect(d / sk, rule)
        new.append(pywt.threshold(d, thr * sk, mode=sorh))
    return pywt.waverec(new, wname, mode=mode)[: x.size]


# --------------------------------------------------------------------------------------------
# select_threshold
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize('rule', RULES)
@pytest.mark.parametrize('n', [1, 2, 5, 31, 32, 33, 64, 257, 1000])
def test_select_threshold_matches_reference(rule, n):
    """All four rules agree with the loop reference for several lengths."""
    rng = np.random.default_rng(1000 + n)
    for scale in (0.5, 1.0, 3.0):
        x = scale * rng.standard_normal(n)
        assert_allclose(select_threshold(x, rule), ref_thselect(x, rule), rtol=1e-12, atol=0)


def test_rigrsure_hand_computed():
    """Rigrsure on a 3-vector matches the hand-computed SURE minimum."""
    # sx2 = [.25, 1, 4]; risks = [1.75, 1.25, 2.25] / 3 -> minimum at |x| = 1.
    assert_allclose(select_threshold([0.5, -1.0, 2.0], 'rigrsure'), 1.0, rtol=0, atol=1e-15)


def test_minimaxi_and_sqtwolog_values():
    """Closed-form rules give the MATLAB formulas."""
    assert select_threshold(np.ones(32), 'minimaxi') == 0.0
    assert_allclose(select_threshold(np.ones(64), 'minimaxi'), 0.3936 + 0.1829 * 6, rtol=1e-14)
    assert_allclose(
        select_threshold(np.ones(100), 'sqtwolog'), math.sqrt(2 * math.log(100)), rtol=1e-14
    )


def test_heursure_branches():
    """Heursure picks sqrt(2 ln n) for pure noise and SURE for a dense signal."""
    n = 256
    hthr = math.sqrt(2 * math.log(n))
    rng = np.random.default_rng(7)
    # Pure unit noise: eta ~ 0 < crit ~ 1.41 -> universal threshold.
    noise = rng.standard_normal(n)
    eta = (noise @ noise - n) / n
    assert eta < (math.log2(n) ** 1.5) / math.sqrt(n)
    assert select_threshold(noise, 'heursure') == pytest.approx(hthr, rel=1e-15)
    # Dense strong signal: eta >> crit -> SURE threshold, well below sqrt(2 ln n).
    dense = noise + 4.0
    thr = select_threshold(dense, 'heursure')
    assert thr < hthr - 0.5
    assert_allclose(thr, ref_thselect(dense, 'rigrsure'), rtol=1e-12)
    assert_allclose(thr, select_threshold(dense, 'rigrsure'), rtol=0, atol=0)


def test_select_threshold_errors():
    """Bad rule, NaN and empty input raise ValueError."""
    with pytest.raises(ValueError, match='heursure'):
        select_threshold([1.0, 2.0], 'sure')
    with pytest.raises(ValueError, match='finite'):
        select_threshold([1.0, np.nan], 'rigrsure')
    with pytest.raises(ValueError, match='at least one'):
        select_threshold([], 'sqtwolog')


# --------------------------------------------------------------------------------------------
# wavelet_denoise
# --------------------------------------------------------------------------------------------


def test_wavelet_denoise_zero_threshold_is_perfect_reconstruction():
    """A zero threshold reconstructs the input exactly."""
    # minimaxi gives thr = 0 for n <= 32; 'one' keeps it at 0 -> identity.
    x = np.random.default_rng(3).normal(size=32)
    for sorh in ('soft', 'hard'):
        y = wavelet_denoise(
            x,
            wavelet='db2',
            level=3,
            threshold_rule='minimaxi',
            threshold_mode=sorh,
            noise_scaling='one',
        )
        assert_allclose(y, x, rtol=0, atol=1e-12)


@pytest.mark.parametrize('rule', RULES)
@pytest.mark.parametrize('scal', ['sln', 'mln', 'one'])
@pytest.mark.parametrize('sorh', ['soft', 'hard'])
def test_wavelet_denoise_matches_reference(rule, scal, sorh):
    """Results follow MATLAB wden for every rule, scaling and mode."""
    rng = np.random.default_rng(11)
    t = np.arange(700)
    x = 0.2 * np.sin(2 * np.pi * t / 300) + (t > 350) * 0.3 + rng.normal(0, 0.1, t.size)
    y = wavelet_denoise(x, threshold_rule=rule, threshold_mode=sorh, noise_scaling=scal)
    ref = ref_wden(x, rule, sorh, scal, 5, 'sym8')
    assert y.shape == x.shape
    assert_allclose(y, ref, rtol=0, atol=1e-12)
    # The thresholding must actually do something here (except when it cannot).
    assert np.max(np.abs(y - x)) > 1e-3


@pytest.mark.parametrize('mode', ['periodization', 'zero', 'smooth'])
def test_wavelet_denoise_boundary_modes_and_odd_length(mode):
    """Other extension modes and odd lengths match the reference."""
    x = np.random.default_rng(5).normal(size=333)
    y = wavelet_denoise(x, wavelet='db4', level=3, boundary_mode=mode)
    assert y.shape == (333,)
    assert_allclose(y, ref_wden(x, 'heursure', 'soft', 'sln', 3, 'db4', mode), rtol=0, atol=1e-12)


def test_wavelet_denoise_reduces_noise_on_tdot_steps():
    """Denoising a noisy piecewise-constant Tdot cuts the RMS error >= 3x."""
    truth = np.repeat([0.0, 0.3, 0.0, -0.3], 500)  # degC/min
    x = truth + np.random.default_rng(2024).normal(0.0, 0.15, truth.size)
    y = wavelet_denoise(x)
    rms_raw = np.sqrt(np.mean((x - truth) ** 2))
    rms_den = np.sqrt(np.mean((y - truth) ** 2))
    assert rms_den * 3.0 <= rms_raw


def test_wavelet_denoise_constant_input_is_unchanged():
    """A constant signal (zero noise estimate) passes without NaN or warnings."""
    x = np.full(600, 0.25)
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        for rule in RULES:
            # No NaN from 0/0; the sym8 filter taps are only ~1e-12 accurate (vanishing moments).
            assert_allclose(wavelet_denoise(x, threshold_rule=rule), x, rtol=0, atol=1e-10)


def test_wavelet_denoise_level_too_high_warns_and_uses_max_level():
    """Too high a level warns and falls back to the maximum level."""
    x = np.random.default_rng(9).normal(size=100)  # sym8: max level floor(log2(100/15)) = 2
    with pytest.warns(UserWarning, match='level'):
        y = wavelet_denoise(x, level=5)
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        y2 = wavelet_denoise(x, level=2)
    assert_array_equal(y, y2)
    assert np.max(np.abs(y - x)) > 1e-3


def test_wavelet_denoise_max_level_zero_returns_copy():
    """A signal too short for any level is returned as a copy."""
    x = np.arange(10.0)
    with pytest.warns(UserWarning):
        y = wavelet_denoise(x)
    assert_array_equal(y, x)
    y[0] = 99.0
    assert x[0] == 0.0


@pytest.mark.parametrize(
    ('x', 'kwargs', 'match'),
    [
        (np.array([0.0, np.nan] * 50), {}, 'finite'),
        (np.array([0.0, np.inf] * 50), {}, 'finite'),
        (np.zeros((10, 10)), {}, '1-D'),
        (np.zeros(100), {'threshold_rule': 'bad'}, 'threshold_rule'),
        (np.zeros(100), {'threshold_mode': 'garrote'}, 'threshold_mode'),
        (np.zeros(100), {'noise_scaling': 'sqrt'}, 'noise_scaling'),
        (np.zeros(100), {'boundary_mode': 'wrap'}, 'boundary_mode'),
        (np.zeros(100), {'wavelet': 'morl'}, 'wavelet'),
        (np.zeros(100), {'level': 0}, 'level'),
    ],
)
def test_wavelet_denoise_errors(x, kwargs, match):
    """Invalid input or options raise ValueError naming the problem."""
    with pytest.raises(ValueError, match=match):
        wavelet_denoise(x, **kwargs)


# --------------------------------------------------------------------------------------------
# Butterworth
# --------------------------------------------------------------------------------------------


def _sos(order=3, cutoff=0.01, period=10.0):
    return signal.butter(order, cutoff, btype='low', output='sos', fs=1.0 / period)


def test_butterworth_filter_matches_scipy_and_online():
    """Offline and online IIR equal sosfilt with steady-state zi."""
    x = np.random.default_rng(4).normal(0.1, 0.2, 400)
    sos = _sos()
    ref = signal.sosfilt(sos, x, zi=signal.sosfilt_zi(sos) * x[0])[0]
    y = butterworth_filter(x, order=3, cutoff_hz=0.01, sample_period_s=10.0)
    assert_allclose(y, ref, rtol=0, atol=1e-12)
    den = ButterworthDenoiser(3, 0.01, 10.0)
    online = np.array([den.update(v) for v in x])
    assert_allclose(online, ref, rtol=0, atol=1e-12)
    assert np.std(y[50:]) < 0.5 * np.std(x[50:])  # it does filter


def test_butterworth_block_equals_one_at_a_time():
    """Block updates equal sample-by-sample updates."""
    x = np.random.default_rng(5).normal(size=300)
    a = ButterworthDenoiser(4, 0.02, 10.0)
    b = ButterworthDenoiser(4, 0.02, 10.0)
    one = np.array([a.update(v) for v in x])
    blocks = np.concatenate(
        [
            b.update_block(x[:1]),
            b.update_block(x[1:117]),
            b.update_block(x[117:117]),
            b.update_block(x[117:]),
        ]
    )
    assert_allclose(blocks, one, rtol=0, atol=1e-12)
    assert a.samples_seen == b.samples_seen == 300


def test_butterworth_constant_input_has_no_transient():
    """Constant input gives constant output from the first sample."""
    den = ButterworthDenoiser(3, 0.01, 10.0)
    assert not den.ready
    out = den.update_block(np.full(200, 0.3))
    assert den.ready
    assert_allclose(out, 0.3, rtol=0, atol=1e-13)
    y = butterworth_filter(np.full(50, -0.7), order=5, cutoff_hz=0.004, sample_period_s=10.0)
    assert_allclose(y, -0.7, rtol=0, atol=1e-13)


def test_butterworth_minus_3db_at_cutoff():
    """The gain is -3 dB at the cut-off and 0 dB at DC."""
    den = ButterworthDenoiser(3, 0.01, 10.0)
    _, h = signal.sosfreqz(den.sos, worN=[0.01, 0.0], fs=0.1)
    assert_allclose(20 * np.log10(np.abs(h)), [-10 * np.log10(2.0), 0.0], rtol=0, atol=1e-9)


def test_butterworth_reset_and_validation():
    """Reset replays identically; bad parameters are rejected."""
    x = np.random.default_rng(6).normal(size=50)
    den = ButterworthDenoiser(2, 0.01, 10.0)
    first = den.update_block(x)
    den.reset()
    assert not den.ready and den.samples_seen == 0
    assert_array_equal(den.update_block(x), first)
    with pytest.raises(ValueError, match='iir_order'):
        ButterworthDenoiser(0, 0.01, 10.0)
    with pytest.raises(ValueError, match='Nyquist'):
        ButterworthDenoiser(3, 0.05, 10.0)
    with pytest.raises(ValueError, match='tdot_period_s'):
        ButterworthDenoiser(3, 0.01, 0.0)
    with pytest.raises(ValueError, match='finite'):
        den.update(float('nan'))


# --------------------------------------------------------------------------------------------
# SlidingWaveletDenoiser
# --------------------------------------------------------------------------------------------


def test_sliding_block_equals_one_at_a_time():
    """Block updates equal sample-by-sample updates bit for bit."""
    x = np.random.default_rng(12).normal(size=200)
    a = SlidingWaveletDenoiser(SMALL)
    b = SlidingWaveletDenoiser(SMALL)
    one = np.array([a.update(v) for v in x])
    blocks = np.concatenate(
        [b.update_block(x[:40]), b.update_block(x[40:41]), b.update_block(x[41:])]
    )
    assert_array_equal(blocks, one)


@pytest.mark.parametrize(
    'settings',
    [
        SMALL,
        DenoiseSettings(delay_samples=0),
        DenoiseSettings(window_samples=480, delay_samples=32),
    ],
)
def test_sliding_full_window_equals_offline_on_window(settings):
    """With a full window the output is wden(window)[-1 - delay]."""
    w, d = settings.window_samples, settings.delay_samples
    x = np.random.default_rng(13).normal(0.0, 0.15, w + 20) + np.linspace(0.0, 0.3, w + 20)
    den = SlidingWaveletDenoiser(settings)
    den.update_block(x[: w - 1])
    assert not den.ready
    kw = dict(
        wavelet=settings.wavelet,
        level=settings.wavelet_level,
        threshold_rule=settings.threshold_rule,
        threshold_mode=settings.threshold_mode,
        noise_scaling=settings.noise_scaling,
        boundary_mode=settings.boundary_mode,
    )
    for k in range(w - 1, x.size):
        out = den.update(x[k])
        assert den.ready
        ref = wavelet_denoise(x[k - w + 1 : k + 1], **kw)[-1 - d]
        assert_allclose(out, ref, rtol=0, atol=1e-12)
    assert_array_equal(den.window, x[-w:])


def test_sliding_memory_bounded():
    """The buffer never grows beyond window_samples."""
    settings = DenoiseSettings()
    den = SlidingWaveletDenoiser(settings)
    x = np.random.default_rng(14).normal(size=3 * settings.window_samples)
    for v in x:
        den.update(v)
        assert den._buf.size == settings.window_samples
        assert den.window.size <= settings.window_samples
    assert den.samples_seen == x.size


def test_sliding_warmup_finite_and_silent():
    """Warm-up outputs are finite, warning-free and use reduced levels."""
    settings = DenoiseSettings(delay_samples=3)
    x = np.random.default_rng(15).normal(0.1, 0.2, 120)
    den = SlidingWaveletDenoiser(settings)
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        out = den.update_block(x)
        const = SlidingWaveletDenoiser(settings).update_block(np.full(60, 0.2))
    assert np.all(np.isfinite(out))
    assert not den.ready
    assert out[0] == x[0]
    # sym8 cannot decompose fewer than 30 samples: running mean.
    assert_allclose(out[:29], np.cumsum(x[:29]) / np.arange(1, 30), rtol=0, atol=1e-12)
    # With 100 samples the level is reduced to dwt_max_level(100, 16) = 2, no warning.
    ref = wavelet_denoise(x[:100], level=2)[-1 - 3]
    assert_allclose(out[99], ref, rtol=0, atol=1e-12)
    assert_allclose(const, 0.2, rtol=0, atol=1e-12)


def test_sliding_warmup_delay_clamped():
    """During warm-up the delayed index is clamped to the oldest sample."""
    settings = DenoiseSettings(wavelet='db4', wavelet_level=3, window_samples=64, delay_samples=40)
    x = np.random.default_rng(16).normal(size=20)
    out = SlidingWaveletDenoiser(settings).update_block(x)
    # Level >= 1 from 14 samples on (db4); index -1-40 clamps to the oldest sample.
    assert_allclose(out[19], wavelet_denoise(x, wavelet='db4', level=1)[0], rtol=0, atol=1e-12)


def test_sliding_reset_replays_identically():
    """Reset restores the initial behaviour."""
    x = np.random.default_rng(17).normal(size=150)
    den = SlidingWaveletDenoiser(SMALL)
    first = den.update_block(x)
    assert den.ready and den.samples_seen == 150
    den.reset()
    assert not den.ready and den.samples_seen == 0 and den.window.size == 0
    assert_array_equal(den.update_block(x), first)


def test_sliding_rejects_nonfinite_without_state_change():
    """Non-finite samples raise and leave the window untouched."""
    den = SlidingWaveletDenoiser(SMALL)
    den.update_block([0.1, 0.2])
    with pytest.raises(ValueError, match='finite'):
        den.update(float('inf'))
    with pytest.raises(ValueError, match='finite'):
        den.update_block([0.3, float('nan')])
    assert den.samples_seen == 2
    assert_array_equal(den.window, [0.1, 0.2])


# --------------------------------------------------------------------------------------------
# DenoiseSettings
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ('field', 'value'),
    [
        ('method', 'median'),
        ('tdot_period_s', 0.0),
        ('tdot_period_s', float('nan')),
        ('tdot_period_s', 'ten'),
        ('wavelet', 'morl'),
        ('wavelet', 'nope'),
        ('wavelet_level', 0),
        ('wavelet_level', 2.5),
        ('threshold_rule', 'sure'),
        ('threshold_mode', 'garrote'),
        ('noise_scaling', 'sqrt'),
        ('boundary_mode', 'wrap'),
        ('window_samples', 0),
        ('window_samples', True),
        ('delay_samples', -1),
        ('delay_samples', 512),
        ('iir_order', 0),
        ('iir_cutoff_hz', 0.0),
        ('iir_cutoff_hz', 0.05),
        ('llr_window_s', 19.0),
        ('llr_window_s', float('inf')),
        ('kalman_rate_walk_degC_per_min_per_sqrt_s', 0.0),
        ('temperature_noise_degC', -0.01),
        ('temperature_quantum_degC', float('nan')),
        ('coil_lag_s', -5.0),
        ('coil_lag_s', 'slow'),
        ('kalman_repeat_rate_degC_per_min', -0.1),
        ('kalman_repeat_rate_degC_per_min', float('nan')),
        ('kalman_repeat_rate_degC_per_min', 'fast'),
        ('kalman_hysteresis_quanta', -0.5),
        ('kalman_hysteresis_quanta', 1.5),
        ('kalman_hysteresis_quanta', float('nan')),
        ('kalman_hysteresis_quanta', 'wide'),
    ],
)
def test_settings_bad_field_named(field, value):
    """Each invalid field raises ValueError naming the field."""
    with pytest.raises(ValueError, match=field):
        DenoiseSettings(**{field: value})


@pytest.mark.parametrize(
    ('field', 'valid'),
    [('kalman_repeat_rate_degC_per_min', (0, 0.1, 5)), ('kalman_hysteresis_quanta', (0, 0.5, 1))],
)
def test_kalman_options_absent_are_off_and_valid_values_load(field, valid):
    """A YAML written before the option loads with it off (0); 0 and the valid values load."""
    assert getattr(DenoiseSettings.from_dict({'method': 'kalman'}), field) == 0.0
    for value in valid:
        settings = DenoiseSettings.from_dict({'method': 'kalman', field: value})
        assert getattr(settings, field) == float(value)


def test_settings_window_minimum():
    """The window minimum follows dwt_max_level and is enforced."""
    assert min_window_samples('sym8', 5) == 480
    for name, level in [('sym8', 5), ('db4', 3), ('haar', 4), ('coif2', 2)]:
        n = min_window_samples(name, level)
        dec_len = pywt.Wavelet(name).dec_len
        assert pywt.dwt_max_level(n, dec_len) >= level > pywt.dwt_max_level(n - 1, dec_len)
    DenoiseSettings(window_samples=480)
    with pytest.raises(ValueError, match=r'window_samples.*480'):
        DenoiseSettings(window_samples=479)
    with pytest.raises(ValueError, match='960'):
        DenoiseSettings(wavelet_level=6)


def test_settings_round_trip_and_keys():
    """to_dict/from_dict round-trip; defaults fill gaps; unknown keys fail."""
    s = DenoiseSettings(
        method='iir',
        tdot_period_s=5,
        wavelet='db4',
        wavelet_level=3,
        threshold_rule='rigrsure',
        threshold_mode='hard',
        noise_scaling='mln',
        boundary_mode='periodization',
        window_samples=100,
        delay_samples=7,
        iir_order=2,
        iir_cutoff_hz=0.02,
        llr_window_s=120,
        kalman_rate_walk_degC_per_min_per_sqrt_s=0.03,
        temperature_noise_degC=0.01,
        temperature_quantum_degC=0.1,
        coil_lag_s=150,
    )
    assert isinstance(s.tdot_period_s, float)
    assert isinstance(s.llr_window_s, float) and isinstance(s.coil_lag_s, float)
    d = s.to_dict()
    assert all(isinstance(v, (str, int, float)) for v in d.values())
    assert DenoiseSettings.from_dict(d) == s
    assert DenoiseSettings.from_dict({}) == DenoiseSettings()
    assert DenoiseSettings.from_dict({'method': 'none'}).window_samples == 512
    with pytest.raises(ValueError, match='bogus_key'):
        DenoiseSettings.from_dict({'method': 'iir', 'bogus_key': 1})
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.method = 'none'  # type: ignore[misc]


# --------------------------------------------------------------------------------------------
# Factories
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ('method', 'cls'),
    [
        ('wavelet', SlidingWaveletDenoiser),
        ('iir', ButterworthDenoiser),
        ('none', PassThroughDenoiser),
    ],
)
def test_make_denoiser(method, cls):
    """The factory returns the class selected by method."""
    den = make_denoiser(dataclasses.replace(SMALL, method=method))
    assert type(den) is cls
    assert isinstance(den, TdotDenoiser)
    assert den.samples_seen == 0
    out = den.update_block(np.linspace(0.0, 1.0, 80))
    assert out.shape == (80,) and den.samples_seen == 80 and den.ready


def test_passthrough():
    """The pass-through denoiser returns its input."""
    den = PassThroughDenoiser()
    assert den.ready
    assert den.update(0.25) == 0.25
    assert_array_equal(den.update_block([1, 2, 3]), [1.0, 2.0, 3.0])
    assert den.samples_seen == 4
    den.reset()
    assert den.samples_seen == 0


def test_denoise_offline_each_method():
    """Offline denoising dispatches on method."""
    truth = np.repeat([0.0, 0.3, 0.0, -0.3], 200)
    x = truth + np.random.default_rng(18).normal(0.0, 0.15, truth.size)
    s = DenoiseSettings()
    assert_array_equal(denoise_offline(x, s), wavelet_denoise(x))
    iir = dataclasses.replace(s, method='iir')
    y = denoise_offline(x, iir)
    online = make_denoiser(iir)
    assert_allclose(y, [online.update(v) for v in x], rtol=0, atol=1e-12)
    assert_allclose(
        y, butterworth_filter(x, order=3, cutoff_hz=0.01, sample_period_s=10.0), rtol=0, atol=0
    )
    none = denoise_offline(x, dataclasses.replace(s, method='none'))
    assert_array_equal(none, x)
    assert none is not x


def test_new_methods_are_selectable_but_not_grid_denoisers():
    """'llr' and 'kalman' are valid methods; they estimate from temperature, not grid Tdot."""
    assert set(GRID_METHODS) == {'wavelet', 'iir', 'none'}
    assert {'llr', 'kalman'} <= set(METHODS)
    for method in ('llr', 'kalman'):
        settings = DenoiseSettings(method=method)
        assert DenoiseSettings.from_dict(settings.to_dict()) == settings
        with pytest.raises(ValueError, match='temperature samples'):
            make_denoiser(settings)
        with pytest.raises(ValueError, match='temperature samples'):
            denoise_offline(np.zeros(10), settings)


def test_measurement_variance_adds_uniform_quantization():
    """R = noise^2 + quantum^2 / 12 (variance of a uniform rounding error)."""
    s = DenoiseSettings(temperature_noise_degC=0.02, temperature_quantum_degC=1 / 16)
    assert s.measurement_variance_degC2 == pytest.approx(0.02**2 + (1 / 16) ** 2 / 12)
    # the new fields default to the behaviour of the original settings
    assert DenoiseSettings().coil_lag_s == 0.0
    d = DenoiseSettings().to_dict()
    assert d['method'] == 'wavelet' and d['window_samples'] == 512
