"""Does the model explain the data? Two tests on the residuals at the optimum, in noise units.

A fit can converge (the optimiser met its criterion) to parameters that explain the data no
better than a wrong model would: the curvature's standard errors then describe the scatter of
the estimate under the model's own noise, not its distance to the truth, and can be thousands of
times too small. Two symptoms show a model that does not explain the data:

* **Too large residuals.** With N independent residuals in units of a correctly stated noise
  level and p fitted parameters, χ² = Σ r² follows a χ² distribution with N − p degrees of
  freedom, so χ²/dof ≈ 1 ± √(2/dof). Its upper tail probability is computed with the
  Wilson–Hilferty cube-root normal approximation (E. B. Wilson, M. M. Hilferty, *Proc. Natl.
  Acad. Sci.* 17 (1931) 684: (χ²/k)^(1/3) is close to normal with mean 1 − 2/(9k) and variance
  2/(9k)), accurate to a few per cent in p for k ≥ 10, which is all a decision at 1e-3 needs.
  The verdict is "too large" only when χ²/dof also exceeds `CHI2_LIMIT` = 2: a stated noise
  level is rarely right to better than ~40 % (√2 in σ), and the test must not fail on that.
  Without a stated noise level σ is estimated from the residuals, χ²/dof = 1 by construction,
  and only the second test can speak.
* **Residuals that are not white.** Independent noise gives residuals without serial
  correlation; a model that misses a feature leaves runs of same-signed residuals. The
  Ljung–Box statistic of each channel's residual sequence (in time order),

      Q = n (n + 2) Σ_{k=1}^{h} ρ̂_k² / (n − k),   ρ̂_k the lag-k sample autocorrelation,

  follows approximately χ² with h degrees of freedom for white residuals (G. M. Ljung,
  G. E. P. Box, *Biometrika* 65 (1978) 297, eq. 2.1; h = min(20, n/5) lags here — their
  recommendation is h of the order of 20 for n of a few hundred or more). The p-value (again
  Wilson–Hilferty) is compared with `ALPHA` after a Bonferroni correction over the channels.
  The figure and the report also give the fraction of the h autocorrelations outside ±2/√n,
  the 95 % band of white noise (G. E. P. Box, G. M. Jenkins, *Time Series Analysis*, 1970,
  §6.2): about 5 % for white residuals.

Estimating p parameters removes ~p degrees of freedom from Q too; with p ≪ h·n that is
negligible here and ignored. Both tests run on residuals that are independent under the noise
model (the `"trajectory"` and `"block"` kinds); smoothed residuals are correlated by
construction, so a fit must end with an independent stage for its verdict to mean anything.
"""

from __future__ import annotations

import math

import numpy as np

# Decision levels (module docstring): a verdict "inadequate" needs p < ALPHA (per test, after
# the Bonferroni correction over channels) and, for χ², also χ²/dof > CHI2_LIMIT.
ALPHA = 1e-3
CHI2_LIMIT = 2.0
MAX_LAGS = 20


def chi2_upper_tail(x: float, k: float) -> float:
    """P(χ²_k ≥ x) by the Wilson–Hilferty approximation (module docstring)."""
    if not (k > 0 and math.isfinite(x)):
        return math.nan
    if x <= 0:
        return 1.0
    z = ((x / k) ** (1.0 / 3.0) - (1.0 - 2.0 / (9.0 * k))) / math.sqrt(2.0 / (9.0 * k))
    return 0.5 * math.erfc(z / math.sqrt(2.0))


def autocorrelation(r: np.ndarray, max_lag: int) -> np.ndarray:
    """Sample autocorrelation ρ̂_k, k = 0 … max_lag, of a sequence about its mean (Box &
    Jenkins 1970, eq. 2.1.12: the lag-k sum divided by the lag-0 sum, so |ρ̂_k| ≤ 1)."""
    r = np.asarray(r, dtype=float) - np.mean(r)
    c0 = float(r @ r)
    if not c0 > 0:
        return np.full(max_lag + 1, np.nan)
    return np.array([1.0] + [float(r[:-k] @ r[k:]) / c0 for k in range(1, max_lag + 1)])


def ljung_box(r: np.ndarray, lags: int | None = None) -> dict:
    """Ljung–Box Q of one residual sequence, its lags h, p-value and the autocorrelations."""
    n = int(np.size(r))
    h = lags if lags is not None else max(1, min(MAX_LAGS, n // 5))
    rho = autocorrelation(r, h)
    k = np.arange(1, h + 1)
    q = float(n * (n + 2) * np.sum(rho[1:] ** 2 / (n - k)))
    band = 2.0 / math.sqrt(n)
    return {
        "n": n,
        "lags": h,
        "Q": q,
        "p_value": chi2_upper_tail(q, h),
        "fraction_outside_2_over_sqrt_n": float(np.mean(np.abs(rho[1:]) > band)),
        "autocorrelation": [float(x) for x in rho],
    }


def assess(residuals: np.ndarray, labels, n_parameters: int, noise_known: bool) -> dict:
    """The adequacy verdict of one fit (module docstring): χ²/dof against the stated noise and
    the whiteness of each channel's residuals, with the reasons when it fails."""
    r = np.asarray(residuals, dtype=float)
    labels = np.asarray(labels)
    n = r.size
    dof = n - n_parameters
    chi2 = float(r @ r)
    reduced = chi2 / dof if dof > 0 else math.nan
    p_chi2 = chi2_upper_tail(chi2, dof) if noise_known and dof > 0 else math.nan
    chi2_too_large = bool(noise_known and reduced > CHI2_LIMIT and p_chi2 < ALPHA)
    names = list(dict.fromkeys(labels.tolist()))
    whiteness = {name: ljung_box(r[labels == name]) for name in names}
    reasons = []
    if chi2_too_large:
        reasons.append(
            f"chi2/dof = {reduced:.3g} against the stated noise (white noise of that level: "
            f"1 ± {math.sqrt(2.0 / dof):.2g}; limit {CHI2_LIMIT:g}): the residuals are "
            f"{math.sqrt(reduced):.3g}x the noise"
        )
    for name, w in whiteness.items():
        corrected = min(1.0, w["p_value"] * len(names))  # Bonferroni over the channels
        w["p_value_corrected"] = corrected
        w["white"] = not corrected < ALPHA
        if not w["white"]:
            reasons.append(
                f"{name}: residuals are not white (Ljung–Box Q = {w['Q']:.3g} over {w['lags']} "
                f"lags, p = {corrected:.2g} < {ALPHA:g}; "
                f"{w['fraction_outside_2_over_sqrt_n']:.0%} of the autocorrelations outside "
                "±2/√n, white noise: ~5 %)"
            )
    return {
        "adequate": not reasons,
        "reasons": reasons,
        "reduced_chi2": reduced,
        "dof": dof,
        "chi2_p_value": p_chi2,
        "chi2_limit": CHI2_LIMIT,
        "alpha": ALPHA,
        "whiteness_test": "Ljung–Box (1978), Bonferroni over channels",
        "whiteness": whiteness,
    }
