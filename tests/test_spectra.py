"""Spectral estimates (jaxdeploy.analysis.spectra) on signals whose answer is known: a tone
between frequency bins, Parseval, and a resonance under impacts far above the save grid's
Nyquist frequency (the case that made deploy_array's reported peak depend on the solver)."""

import numpy as np
import pytest

from jaxdeploy.analysis.spectra import interval_mean_rate, peak_frequency, welch_psd


def test_peak_of_a_tone_between_bins_and_parseval():
    fs, f0, amp = 1000.0, 91.3, 2.0  # 91.3 Hz lies between the 5 Hz bins of a 0.2 s segment
    t = np.arange(0.0, 1.5, 1.0 / fs)
    x = amp * np.sin(2 * np.pi * f0 * t + 0.4)
    # The parabola through three log-power bins of a Hann main lobe: error a few % of a bin.
    assert peak_frequency(t, x, segment=0.2) == pytest.approx(f0, abs=0.25)
    f, psd = welch_psd(t, x, 0.2)
    # Parseval: the density integrates to the variance A²/2 (the Hann window's energy is
    # normalised out, so this holds for the averaged segments too).
    assert np.sum(psd) * (f[1] - f[0]) == pytest.approx(amp**2 / 2, rel=0.02)


def test_interval_mean_rate_is_exact_for_a_polynomial_and_keeps_trailing_axes():
    t = np.array([0.0, 0.1, 0.3, 0.6])
    x = np.stack([t**2, 3 * t], axis=-1)
    starts, rate = interval_mean_rate(t, x)
    np.testing.assert_array_equal(starts, t[:-1])
    np.testing.assert_allclose(rate[:, 0], t[1:] + t[:-1], rtol=1e-14)  # (b² − a²)/(b − a)
    np.testing.assert_allclose(rate[:, 1], 3.0, rtol=1e-14)


def _ringing_with_impacts(seed, fs_fine=1e6, t_end=1.5, f0=90.0):
    """Acceleration a(t) = 10 e^{−5 t} sin(2π f0 t) [m/s²] plus 600 half-sine pulses of 10 µs
    (impacts: 500 m/s² peak, random times and signs) on a 1 µs grid, and the velocity
    v = ∫ a dt (trapezoid on that grid). The pulses' own spectrum is flat to ~50 kHz and, in
    the band, several times below the resonance's peak."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, t_end, 1.0 / fs_fine)
    a = 10.0 * np.exp(-5.0 * t) * np.sin(2 * np.pi * f0 * t)
    width, count = 10e-6, 600
    starts, signs = rng.uniform(0, t_end - width, count), rng.choice([-1, 1], count)
    for start, sign in zip(starts, signs, strict=True):
        first = int(np.ceil(start * fs_fine))
        phase = (t[first : first + int(width * fs_fine) + 1] - start) / width
        phase = phase[phase < 1.0]
        a[first : first + len(phase)] += sign * 500.0 * np.sin(np.pi * phase)
    v = np.concatenate([[0.0], np.cumsum(0.5 * (a[1:] + a[:-1])) / fs_fine])
    return t, a, v


def test_resonance_under_impacts_from_the_saved_velocities():
    """Saved at 1 kHz, the impacts fold onto 0–500 Hz when the acceleration is point-sampled
    (a sample that falls in a pulse reads up to 500 m/s²); the interval-mean acceleration from
    the saved velocities averages over the interval before sampling and finds the 90 Hz
    resonance in every record."""
    step = 1000  # 1 µs grid → 1 kHz saves
    from_velocities, point_sampled = [], []
    for seed in range(8):
        t, a, v = _ringing_with_impacts(seed)
        starts, mean_acc = interval_mean_rate(t[::step], v[::step])
        from_velocities.append(peak_frequency(starts, mean_acc, segment=0.1))
        point_sampled.append(peak_frequency(t[::step], a[::step], segment=0.1))
    np.testing.assert_allclose(from_velocities, 90.0, atol=2.5)  # a quarter of a 10 Hz bin
    # The records are hard: point samples of the same signals miss the resonance in some.
    assert sum(abs(f - 90.0) > 5.0 for f in point_sampled) >= 2, point_sampled


def test_short_records_and_bad_segment():
    t = np.linspace(0, 1e-3, 5)
    assert np.isnan(peak_frequency(t, np.sin(t), segment=0.2))
    with pytest.raises(ValueError, match="segment"):
        welch_psd(np.linspace(0, 1, 100), np.zeros(100), 0.0)
