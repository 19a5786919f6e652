"""Gaussian moments `F_n(h)` of the Greenwood–Williamson model, evaluated smoothly in JAX.

Two quadratures, each used where it is accurate:

* `h >= -H_SWITCH` ("shallow"): `F_n(h) = ∫_0^T t^n φ(t + h) dt` with `t = u²`, i.e.
  `∫_0^√T 2 u^(2n+1) φ(u² + h) du`, `T = 12 + max(0, −h)`, 64-node Gauss–Legendre. The
  substitution removes the `t^n` endpoint singularity, so the integrand is analytic and the rule
  converges to round-off (checked against mpmath in the tests; docs/contact.md).
* `h < -H_SWITCH` ("deep"): every asperity is in contact, `(s − h)^n` has no kink on the support
  of φ, so `F_n(h) = E[(Z − h)^n]` is integrated over `s ∈ [−L, L]` directly. This branch is
  needed because the shallow rule's window grows with `−h` and its nodes stop resolving the
  Gaussian for `h ≪ −10` (deep contact, or σ → 0).

Both branches are smooth, jit/vmap/grad-safe, and each only ever sees arguments in its own range
(clipped), so no NaN can leak through `jnp.where` into a gradient (JAX FAQ, "Gradients
contain NaN where using `where`").
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import erfc

__all__ = ["gaussian_moment", "gaussian_smoothed_power", "positive_power"]

_NODES = 64
_GL_X, _GL_W = np.polynomial.legendre.leggauss(_NODES)
_SQRT_2PI = float(np.sqrt(2.0 * np.pi))

# Below h = -H_SWITCH the deep rule is used. Its rule spans s in [-L, L]; the nearest kink of
# (s - h)^n is then at distance >= H_SWITCH - L from the interval, which keeps Gauss-Legendre
# converging geometrically (Bernstein ellipse radius ~1.6 -> error ~1e-26), while φ(L) ~ 1e-18
# makes the truncated tails negligible.
H_SWITCH = 10.0
_L = 9.0
# φ(h) underflows to exactly 0 in float64 beyond h ≈ 38.6; clipping keeps (u² + h)² finite.
_H_MAX = 60.0

_DEEP_S = _L * _GL_X
_DEEP_W = _L * _GL_W * np.exp(-0.5 * _DEEP_S**2) / _SQRT_2PI
# Normalising the weights makes E[1] = 1 to round-off, so σ = 0 reproduces Hertz.
_DEEP_W = _DEEP_W / _DEEP_W.sum()


def _phi(x):
    return jnp.exp(-0.5 * x * x) / _SQRT_2PI


def positive_power(base, n: float):
    """`base_+^n`: `base**n` where `base > 0`, else 0, with a finite gradient (0) at `base <= 0`.

    A plain `jnp.maximum(base, 0)**n` has an infinite or NaN gradient at 0 for `n < 1`, and
    `jnp.where` alone would still differentiate the untaken branch (JAX FAQ).

    **Arguments:** `base` (array), `n` (static Python number ≥ 0).

    **Returns:** `max(base, 0)**n`, with `0**0 = 0` (a Heaviside step for `n = 0`); NaN where
    `base` is NaN. Every comparison with NaN is false, so the conditions are written to send
    a NaN down the `base**n` branch: a NaN state must give a NaN force, never 0.
    """
    base = jnp.asarray(base, dtype=float)
    if n == 0.0:
        step = jnp.where(base > 0, 1.0, jnp.where(jnp.isnan(base), base, 0.0))
        return step.astype(jnp.result_type(base, float))
    gap = base <= 0
    safe = jnp.where(gap, 1.0, base)
    return jnp.where(gap, 0.0, safe**n)


def _shallow(h, n: float):
    """`F_n(h)` by the `t = u²` Gauss–Legendre rule; accurate for `-H_SWITCH <= h`."""
    # `where`, not `clip`: clip passes only half the gradient at the boundary itself. The
    # conditions select the clamp only when it is true, so a NaN h stays NaN (a NaN state
    # must give a NaN force, not the force at a clamp).
    h = jnp.where(h < -H_SWITCH, -H_SWITCH, h)
    h = jnp.where(h > _H_MAX, _H_MAX, h)
    # Window in t: 12 + max(0, -h) covers the Gaussian (phi < 1e-31 beyond). For h > 5 the
    # integrand ~ t^n exp(-h t) lives on t ≲ 1/h, so the window shrinks to 60/h (truncation
    # ~ 60^n e^-60 relative) to keep the nodes on it; otherwise the error grows to 1e-3 at h = 30.
    t_max = jnp.where(h > 5.0, 60.0 / jnp.maximum(h, 5.0), 12.0 + jnp.maximum(0.0, -h))
    # Nodes u_k = √t_max ξ_k, ξ_k = (x_k + 1)/2 on (0, 1), weights ½ √t_max w_k: the sum is
    # t_max^(n+1) Σ_k w_k ξ_k^(2n+1) φ(t_max ξ_k² + h), with w_k ξ_k^(2n+1) constants of the
    # rule, so the 64 powers per call of the direct form become one; 64 exponentials remain.
    xi = 0.5 * (_GL_X + 1.0)
    scaled_weights = _GL_W * xi ** (2.0 * n + 1.0)
    total = jnp.sum(scaled_weights * _phi(t_max[..., None] * (xi * xi) + h[..., None]), axis=-1)
    return _power(t_max, n) * t_max * total


def _power(base, n: float):
    """`base**n` for `base > 0` and static `n`: integer powers by multiplication and
    half-integer ones as `base^⌊n⌋ √base` (a `pow` is several times dearer on CPU)."""
    if float(n).is_integer():
        return jax.lax.integer_pow(base, int(n)) if n else jnp.ones_like(base)
    if float(2 * n).is_integer():
        whole = int(n - 0.5)
        root = jnp.sqrt(base)
        return root if whole == 0 else jax.lax.integer_pow(base, whole) * root
    return base**n


def _deep(shift, scale, n: float):
    """`E[(shift + scale·Z)^n]` by Gauss–Legendre over `Z ∈ [−L, L]`, for `shift > L·scale`.

    Written without dividing by `scale`, so `scale = 0` gives `shift^n` (Hertz, to round-off).
    """
    base = shift[..., None] + scale[..., None] * _DEEP_S
    # Callers guarantee shift > L·scale, i.e. base > 0 on every node; the guard keeps an
    # unselected branch (under `where`) finite.
    safe = jnp.where(base > 0, base, 1.0)
    return jnp.sum(_DEEP_W * jnp.where(base > 0, _power(safe, n), 0.0), axis=-1)


def _check_order(n) -> float:
    if not isinstance(n, int | float) or isinstance(n, bool):
        raise TypeError(f"order n must be a static Python number, got {type(n).__name__}.")
    n = float(n)
    if not n > -1.0:
        raise ValueError(f"order n = {n!r} is invalid: F_n(h) diverges unless n > -1.")
    return n


def gaussian_moment(h, n: float):
    """Gaussian moment `F_n(h) = ∫_h^∞ (s − h)^n φ(s) ds` of the Greenwood–Williamson model.

    **Arguments:**

    - `h`: separation in units of σ (array; broadcasts). Positive `h` = surfaces apart.
    - `n`: order, a static Python number with `n > −1` (0, ½, 1, 3/2, 2, 5/2 are the usual ones).

    **Returns:** `F_n(h)`, same shape as `h`. Smooth in `h`; `dF_n/dh = −n F_(n−1)` (n ≠ 0),
    `dF_0/dh = −φ(h)`. Underflows to exactly 0 for `h ≳ 38` (never NaN); for `h → −∞` it tends
    to `(−h)^n`. Relative error ≤ 1e-12 against mpmath over `h ∈ [−10, 8]` (tested ≤ 1e-8).

    Equations: `F_0 = ½ erfc(h/√2)`; for other `n`, `F_n(h) = ∫_0^√T 2u^(2n+1) φ(u² + h) du`
    (`T = 12 + max(0, −h)`) for `h ≥ −10`, and `F_n(h) = E[(Z − h)^n]` over `|Z| ≤ 9` below.

    **References:**

    - Greenwood, Williamson, *Proc. R. Soc. A* 295 (1966) 300 (definition of F_n).
    - docs/contact.md, "Gaussian moments" (the `t = u²` rule and its accuracy against mpmath).
    """
    n = _check_order(n)
    h = jnp.asarray(h, dtype=float)
    if n == 0.0:
        return 0.5 * erfc(h / np.sqrt(2.0))
    deep_h = jnp.minimum(h, -H_SWITCH)
    deep = _deep(-deep_h, jnp.ones_like(h), n)
    return jnp.where(h < -H_SWITCH, deep, _shallow(h, n))


def gaussian_smoothed_power(x, sigma, n: float):
    """Hertz power law averaged over Gaussian heights: `E[(x + σZ)_+^n] = σ^n F_n(−x/σ)`.

    This is the Greenwood–Williamson average that turns the Hertz law `K δ_+^n` into the
    rough-surface law (docs/contact.md); it is written so that `σ = 0` is allowed and gives
    `x_+^n` (to round-off), with finite gradients in `x` and `σ` there.

    **Arguments:**

    - `x`: mean interference (m), e.g. `δ − s0 σ`.
    - `sigma`: standard deviation σ ≥ 0 of the combined peak heights (m).
    - `n`: static exponent, `n ≥ 0`.

    **Returns:** `E[(x + σZ)_+^n]` (units m^n), broadcast over `x` and `sigma`.

    **References:** Greenwood & Williamson, *Proc. R. Soc. A* 295 (1966) 300.
    """
    n = _check_order(n)
    if n < 0.0:
        raise ValueError(f"order n = {n!r} is invalid: the smoothed power needs n >= 0.")
    x, sigma = jnp.broadcast_arrays(jnp.asarray(x, dtype=float), jnp.asarray(sigma, dtype=float))
    # Deep: every asperity within ±L σ is in contact (includes σ = 0 with x > 0). No division
    # by σ on this path, so σ → 0 never produces inf/NaN.
    deep_mask = x > H_SWITCH * sigma
    deep_x = jnp.where(deep_mask, x, H_SWITCH * sigma + 1.0)
    deep = _deep(deep_x, sigma, n)
    # Shallow: needs σ > 0; a dummy σ = 1 keeps the unselected branch (and its gradient) finite.
    positive = sigma > 0
    safe_sigma = jnp.where(positive, sigma, 1.0)
    shallow_h = jnp.where(deep_mask, -H_SWITCH, -x / safe_sigma)
    # shallow_h ≥ −H_SWITCH here, so only the shallow rule of `gaussian_moment` is needed.
    moment = 0.5 * erfc(shallow_h / np.sqrt(2.0)) if n == 0.0 else _shallow(shallow_h, n)
    shallow = _power(safe_sigma, n) * moment
    # σ = 0 and x <= 0: nominal gap without roughness -> Hertz gives exactly 0 (a NaN x keeps
    # its NaN, carried through the shallow branch).
    shallow = jnp.where(positive | jnp.isnan(x), shallow, 0.0)
    return jnp.where(deep_mask, deep, shallow)
