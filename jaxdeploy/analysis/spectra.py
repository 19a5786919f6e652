"""Spectra of sampled signals: a Hann-windowed amplitude spectrum, Welch's averaged periodogram,
and a spectral peak that does not depend on the save grid or on a chaotic record's details.

Why the peak is defined this way (measured in docs/spectral_peak.md): deploy_array's post-lock
panel acceleration is a train of impacts, flat in frequency far above the kHz range, on top of
the locked structure's ~90 Hz mode. Sampled at the save grid (1 kHz by default), such a signal
is aliased: everything above the Nyquist frequency folds onto 0–500 Hz. And the single
Hann-windowed periodogram of the whole post-lock record resolves ~1 Hz, so its maximum picks
one of many ripples — interference between individual rattle impacts, which are chaotic — out
of a ~10 Hz-wide resonance. Together they made the reported peak 85 Hz with one solver and
200 Hz with another (and ~200 Hz with the first at a tighter tolerance). Hence:

* `interval_mean_rate`: the mean of dx/dt over each save interval, from the saved x (for an
  acceleration: from the saved velocities). It is what an integrating sensor reports, it
  counts every impulse between samples exactly, and it low-passes (a boxcar: gain
  |sinc(f/f_s)|) before sampling, so content above the Nyquist frequency folds back attenuated.
* `welch_psd`: Welch's (1967) averaged modified periodogram — Hann-windowed segments of fixed
  length, half overlapping, mean removed per segment, power averaged — whose resolution is
  set by the segment length, not by the record length.
* `peak_frequency`: its largest peak, located between bins by a parabola through the log
  power at the maximum bin and its two neighbours.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
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


def _array_module(x):
    """jax.numpy for JAX arrays (traced or not: the spectra then differentiate), else numpy."""
    return jnp if isinstance(x, jax.Array) else np


def interval_mean_rate(t, x):
    """Mean rate of change of `x` over each interval of the samples:

    r_k = (x_{k+1} − x_k) / (t_{k+1} − t_k) = (1/Δt) ∫_{t_k}^{t_{k+1}} ẋ dt,

    for an acceleration from saved velocities. **Returns:** `(t_k, r_k)` (interval start
    times; `len(t) − 1` values; `x` may have trailing axes; a JAX `x` gives a JAX `r_k`).
    """
    xp = _array_module(x)
    t, x = np.asarray(t, dtype=float), xp.asarray(x, dtype=float)
    dt = np.diff(t).reshape((-1,) + (1,) * (x.ndim - 1))
    return t[:-1], xp.diff(x, axis=0) / dt


def welch_psd(t, x, segment):
    """One-sided power spectral density of `x(t)` (uniform samples) by Welch's method (Welch
    1967, IEEE Trans. Audio Electroacoust. AU-15, 70–73): the record is cut into segments of
    `segment` [s] overlapping by half, each segment's mean is removed and it is Hann-windowed
    (w), and the periodograms 2 |DFT(w x)|² / (f_s Σ w²) are averaged. A record shorter than
    one segment is one segment.

    **Arguments:** `t` concrete sample times; `x` `(N,)` or `(N, ...)` (trailing axes are
    spectra of their own); numpy, or a JAX array (possibly traced: the PSD differentiates).

    **Returns:** `(frequencies [Hz], psd [x² / Hz])`, psd `(F, ...)`; the frequency resolution
    is 1/`segment`.
    """
    if not segment > 0:
        raise ValueError(f"segment = {segment!r} is invalid: it must be > 0 s")
    xp = _array_module(x)
    t, x = np.asarray(t, dtype=float), xp.asarray(x, dtype=float)
    dt = float(np.mean(np.diff(t)))
    n = min(len(x), max(8, int(round(segment / dt))))
    starts = np.arange(0, len(x) - n + 1, max(1, n // 2))
    segments = x[starts[:, None] + np.arange(n)]  # (S, n, ...)
    segments = segments - segments.mean(axis=1, keepdims=True)
    window = np.hanning(n)
    spectra = xp.fft.rfft(segments * window.reshape((1, n) + (1,) * (x.ndim - 1)), axis=1)
    # |z|² as re² + im²: differentiable where a bin is exactly 0, unlike abs.
    power = xp.sum(xp.real(spectra) ** 2 + xp.imag(spectra) ** 2, axis=0)
    psd = 2.0 * power / (len(starts) * np.sum(window**2) / dt)
    return np.fft.rfftfreq(n, dt), psd


def peak_frequency(t, x, *, segment, f_min=1.0):
    """Frequency [Hz] of the largest peak of `welch_psd(t, x, segment)` at or above `f_min`.

    The maximum bin k is refined by the vertex of the parabola through (f, ln P) at bins
    k − 1, k, k + 1 (a Hann main lobe is close to a Gaussian, whose logarithm is a parabola):
    f = f_k + Δf (ln P_{k−1} − ln P_{k+1}) / (2 (ln P_{k−1} − 2 ln P_k + ln P_{k+1})).
    NaN for fewer than 8 samples.
    """
    if len(np.asarray(t)) < 8:
        return float("nan")
    freqs, psd = welch_psd(t, x, segment)
    keep = np.flatnonzero(freqs >= f_min)
    if len(keep) == 0:
        return float("nan")
    k = int(keep[np.argmax(psd[keep])])
    if k == 0 or k == len(freqs) - 1 or not np.all(psd[k - 1 : k + 2] > 0):
        return float(freqs[k])
    lo, mid, hi = np.log(psd[k - 1 : k + 2])
    curvature = lo - 2.0 * mid + hi
    # The clip keeps the vertex within the maximum bin when a neighbour below f_min is higher.
    offset = float(np.clip(0.5 * (lo - hi) / curvature, -0.5, 0.5)) if curvature < 0 else 0.0
    return float(freqs[k] + offset * (freqs[1] - freqs[0]))
