"""Amplitude spectra of sampled signals (Hann window)."""

from __future__ import annotations

import numpy as np


def amplitude_spectrum(t, x):
    """One-sided amplitude spectrum of `x(t)` sampled uniformly, Hann-windowed, mean removed.

    **Returns:** `(frequencies [Hz], amplitudes)`; amplitudes are corrected for the window's
    coherent gain, so a sinusoid of amplitude A shows a peak of about A.
    """
    t, x = np.asarray(t), np.asarray(x)
    if len(t) < 8:
        return np.zeros(1), np.zeros(1)
    dt = float(np.mean(np.diff(t)))
    window = np.hanning(len(x))
    spectrum = np.fft.rfft((x - x.mean()) * window)
    amplitude = 2.0 * np.abs(spectrum) / window.sum()
    return np.fft.rfftfreq(len(x), dt), amplitude


def peak_frequency(t, x, f_min=1.0):
    """Frequency of the largest spectral peak above `f_min` Hz."""
    freqs, amp = amplitude_spectrum(t, x)
    mask = freqs >= f_min
    if not mask.any():
        return float("nan")
    return float(freqs[mask][np.argmax(amp[mask])])
