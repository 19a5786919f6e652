"""The eccentricity of a clearance joint over one accepted step, interpolated to locate the
contact onset, the peak of the approach speed and the separation inside the step
(`RevoluteClearance`'s v⁻ memory).

Why e and not δ. The penetration δ = |e| − c has a kink at the bearing's centre, e = 0: a
journal flying through the centre at speed v has δ̇ = −v before it and +v after it. A cubic
Hermite interpolant of δ through a step that holds both the centre passage and a far-side
onset cannot follow that kink, and the approach speed v⁻ read off it was wrong by 46 % (1.307
vs 0.894 m/s, E = 1 GPa impact scene, tests/test_robustness.py), a wrong answer no error
estimate sees (it lives in the memory, not in the state); event location does not help since
the retried step still starts before the centre. The eccentricity vector e(t) = r_Pj − r_Pi
is smooth through the centre. So e is interpolated by the cubic Hermite of its end values
(e, ė), s = (t − t₀)/h ∈ [0, 1],

    e(s) = e₀ + h (a s + c₁ s²/2 + c₂ s³/3),   ė(s) = a + c₁ s + c₂ s²,
    c₁ = 6m − 4a − 2b,   c₂ = 3a + 3b − 6m,   a = ė₀, b = ė₁, m = (e₁ − e₀)/h,

and δ and δ̇ are the joint's own functions of it,

    δ(s) = sqrt(e·e + ε²) − c,   δ̇(s) = ė·e / sqrt(e·e + ε²),

smooth wherever e is (the ε of `RevoluteClearance.eccentricity_smoothing` keeps them finite
and differentiable at e = 0). Away from the centre this is as accurate as the Hermite of δ
(both O(h⁴) for a smooth path; exact when e is a cubic in t); through the centre it is right
where that one was not. δ(s) and δ̇(s) are no longer a cubic and a parabola, so the onset
(δ = level) and the peak (δ̈ = 0) are found numerically: the step is sampled at `GRID` + 1
points to bracket the last upward crossing and the largest δ̇, and a safeguarded Newton
iteration (Newton inside the bracket, bisection when Newton leaves it; fixed `NEWTON`
iterations in a `lax.fori_loop`, without derivatives) refines the bracket to round-off. Derivatives
with respect to the parameters: the onset is the root of δ(s) = level, so one Newton step
from the (gradient-stopped) converged root carries the implicit-function derivative
ds/dθ = −∂_θδ / δ'(s); at the peak δ̈ = 0, so v⁻ = δ̇(s_peak) needs no derivative of s_peak
(envelope theorem) and the peak's location is gradient-stopped.

`m` carries the world positions' round-off divided by h: a step that lands on a requested
time can be 1e-19 s long, where (e₁ − e₀)/h is pure round-off and can exceed the true speed
by orders of magnitude. Where that round-off exceeds 1e-6 of
the end speeds, m is the trapezoid value (a + b)/2: ė is then linear over the step and
nothing a step that short can resolve is lost.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

GRID = 16  # samples of the step that bracket the onset and the peak of δ̇
NEWTON = 10  # safeguarded Newton iterations inside a bracket (1/16 of the step wide)


class StepEccentricity:
    """e(s) over one step of length `step` (s) from its end values `(e₀, ė₀)`, `(e₁, ė₁)`
    (2-vectors, m and m/s), with δ = |e|_ε − `clearance` and δ̇ on it (module docstring).
    `roundoff` (m) is the round-off of e₁ − e₀."""

    def __init__(self, e0, rate0, e1, rate1, step, clearance, smoothing, roundoff=0.0):
        speed = jnp.sum(jnp.abs(rate0)) + jnp.sum(jnp.abs(rate1))
        trusted = roundoff < 1e-6 * step * speed
        mean = jnp.where(trusted, (e1 - e0) / jnp.where(trusted, step, 1.0), 0.5 * (rate0 + rate1))
        self.e0, self.rate0, self.step = e0, rate0, step
        self.c1 = 6.0 * mean - 4.0 * rate0 - 2.0 * rate1
        self.c2 = 3.0 * rate0 + 3.0 * rate1 - 6.0 * mean
        self.clearance, self.smoothing = clearance, smoothing

    # --- e(s) and its s-derivatives; every s may be an array (the result then gains its shape)

    def _derivatives(self, s):
        """(u, u', u'', u''') with u(s) = e(s) and ' = d/ds, each of shape s.shape + (2,)."""
        s = jnp.asarray(s)[..., None]
        h = self.step
        u = self.e0 + h * (self.rate0 * s + self.c1 * s**2 / 2 + self.c2 * s**3 / 3)
        u1 = h * (self.rate0 + self.c1 * s + self.c2 * s**2)
        u2 = h * (self.c1 + 2.0 * self.c2 * s)
        u3 = jnp.broadcast_to(2.0 * h * self.c2, u.shape)
        return u, u1, u2, u3

    def _radius(self, u):
        return jnp.sqrt(jnp.sum(u * u, axis=-1) + self.smoothing**2)

    def eccentricity(self, s):
        return self._derivatives(s)[0]

    def penetration(self, s):
        """δ(s) = |e(s)|_ε − c."""
        return self._radius(self.eccentricity(s)) - self.clearance

    def rate(self, s):
        """δ̇(s) = ė·e/|e|_ε (m/s)."""
        u, u1, _, _ = self._derivatives(s)
        return jnp.sum(u * u1, axis=-1) / (self.step * self._radius(u))

    def _rate_slopes(self, s):
        """(g', g'') with g = h δ̇ = A/r, A = u·u', r = |u|_ε: g' = A'/r − A²/r³,
        g'' = A''/r − 3AA'/r³ + 3A³/r⁵ (A' = u'·u' + u·u'', A'' = 3u'·u'' + u·u''')."""
        u, u1, u2, u3 = self._derivatives(s)
        r = self._radius(u)
        a0 = jnp.sum(u * u1, axis=-1)
        a1 = jnp.sum(u1 * u1 + u * u2, axis=-1)
        a2 = jnp.sum(3.0 * u1 * u2 + u * u3, axis=-1)
        return a1 / r - a0**2 / r**3, a2 / r - 3.0 * a0 * a1 / r**3 + 3.0 * a0**3 / r**5

    # --- events

    def _frozen(self):
        """This path with every input gradient-stopped: the bracketing and the Newton
        iterations carry no derivative (module docstring), so no tangent enters their loops."""
        frozen = object.__new__(StepEccentricity)
        for name, value in vars(self).items():
            setattr(frozen, name, jax.lax.stop_gradient(value))
        return frozen

    def _onset_slope(self, s):
        """dδ/ds = u·u'/|u|_ε."""
        u, u1, _, _ = self._derivatives(s)
        return jnp.sum(u * u1, axis=-1) / self._radius(u)

    def crossing(self, level):
        """The s ∈ [0, 1] where δ(s) rises through `level` for the last time in the step
        (δ₀ ≤ level < δ₁; the onset of the contact current at the step's end)."""
        frozen = self._frozen()
        samples = jnp.linspace(0.0, 1.0, GRID + 1)
        below = frozen.penetration(samples) <= level
        k = jnp.max(jnp.where(below[:-1], jnp.arange(GRID), 0))

        def newton_or_bisect(_, bracket):
            lo, hi, x = bracket
            f = frozen.penetration(x) - level
            slope = frozen._onset_slope(x)
            lo, hi = jnp.where(f <= 0, x, lo), jnp.where(f <= 0, hi, x)
            newton = x - f / jnp.where(slope > 0, slope, jnp.inf)
            ok = (slope > 0) & (newton > lo) & (newton < hi)
            return lo, hi, jnp.where(ok, newton, 0.5 * (lo + hi))

        lo, hi = samples[k], samples[k + 1]
        _, _, x = jax.lax.fori_loop(0, NEWTON, newton_or_bisect, (lo, hi, 0.5 * (lo + hi)))
        # One Newton step from the converged root: the implicit derivative ds/dθ.
        slope = self._onset_slope(x)
        step = (self.penetration(x) - level) / jnp.where(slope > 0, slope, jnp.inf)
        return jnp.clip(x - step, 0.0, 1.0)

    def separation(self, level):
        """The first s ∈ [0, 1] where δ(s) falls through `level` (δ₀ > level ≥ δ₁: the
        contact current at the step's start ended inside it), for event location only (no
        derivative: nothing is computed from it but where the step should end)."""
        frozen = self._frozen()
        samples = jnp.linspace(0.0, 1.0, GRID + 1)
        below = frozen.penetration(samples) <= level
        k = jnp.argmax(below[1:])  # the first sample interval whose right end is below

        def newton_or_bisect(_, bracket):
            lo, hi, x = bracket
            f = frozen.penetration(x) - level
            slope = frozen._onset_slope(x)
            lo, hi = jnp.where(f > 0, x, lo), jnp.where(f > 0, hi, x)
            newton = x - f / jnp.where(slope < 0, slope, -jnp.inf)
            ok = (slope < 0) & (newton > lo) & (newton < hi)
            return lo, hi, jnp.where(ok, newton, 0.5 * (lo + hi))

        lo, hi = samples[k], samples[k + 1]
        _, hi, _ = jax.lax.fori_loop(0, NEWTON, newton_or_bisect, (lo, hi, 0.5 * (lo + hi)))
        return hi  # at or just past the crossing: δ(hi) ≤ level

    def peak(self, s_start):
        """`(s, inside)`: the largest δ̇ over [s_start, 1], located on `GRID` + 1 samples and
        refined by Newton on δ̈ = 0 in the bracket around the largest sample; `inside`:
        whether it is a maximum strictly inside (s_start, 1), above both ends. Carries no
        derivative (at a maximum, v⁻ = δ̇(s) does not need one)."""
        frozen = self._frozen()
        s_start = jax.lax.stop_gradient(s_start)
        samples = s_start + (1.0 - s_start) * jnp.linspace(0.0, 1.0, GRID + 1)
        rates = frozen.rate(samples)
        k = jnp.argmax(rates)

        def newton_or_bisect(_, bracket):
            lo, hi, x = bracket
            slope, curvature = frozen._rate_slopes(x)
            # δ̇ still rising at x: the peak is beyond it; falling: before it.
            lo, hi = jnp.where(slope > 0, x, lo), jnp.where(slope > 0, hi, x)
            newton = x - slope / jnp.where(curvature < 0, curvature, -jnp.inf)
            ok = (curvature < 0) & (newton > lo) & (newton < hi)
            return lo, hi, jnp.where(ok, newton, 0.5 * (lo + hi))

        bracket = (samples[jnp.maximum(k - 1, 0)], samples[jnp.minimum(k + 1, GRID)], samples[k])
        _, _, x = jax.lax.fori_loop(0, NEWTON, newton_or_bisect, bracket)
        # Never worse than the best sample (a bracket without a sign change of δ̈ converges to
        # its end, which need not be a maximum).
        x = jnp.where(frozen.rate(x) >= rates[k], x, samples[k])
        ends = jnp.maximum(rates[0], rates[-1])
        inside = (x > s_start) & (x < 1.0) & (frozen.rate(x) > ends)
        return x, inside

    def max_rate(self, s_start):
        """max of δ̇(s) over s ∈ [s_start, 1]: the ends, or the peak inside."""
        vertex, inside = self.peak(s_start)
        ends = jnp.maximum(self.rate(s_start), self.rate(1.0))
        return jnp.where(inside, jnp.maximum(ends, self.rate(vertex)), ends)
