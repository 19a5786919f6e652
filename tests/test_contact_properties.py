"""Property-based tests (hypothesis) of the contact laws over their whole valid domain.

Domain (SI), what the scenes accept (`ParamSpec` ranges) and beyond: K 1e5–1e14 N/m^1.5
(E 1 MPa–10 TPa on mm pins); σ 0–125 µm (Ra ≤ 100 µm); penetration δ within ±500 µm; offset s0
0–6; restitution c_e in (0, 1]; approach speeds 0–100 m/s; penetration rates ±100 m/s; μ 0–2;
sliding speeds ±100 m/s; normal forces 0–1e9 N. Each property is checked against something that does
not come from the code under test: an inequality of convex functions, a Taylor expansion of the
Gaussian average, the fundamental theorem of calculus, a symmetry.
"""

import math

import jax
import jax.numpy as jnp
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxdeploy import contact

SETTINGS = settings(max_examples=30, deadline=None, derandomize=True)

stiffness = st.floats(1e5, 1e14)
sigma = st.one_of(st.just(0.0), st.floats(1e-9, 1.25e-4))
delta = st.floats(-5e-4, 5e-4)
offset = st.floats(0.0, 6.0)
restitution = st.floats(1e-6, 1.0)
speed = st.floats(0.0, 100.0)
rate = st.floats(-100.0, 100.0)
mu = st.floats(0.0, 2.0)
N = 1.5  # the exponent used throughout; the laws take it as a static number


def _elastic(k, s, s0):
    return contact.RoughElastic(k, s, offset=s0) if s0 is not None else contact.HertzElastic(k)


@jax.jit
def _rough(k, s, s0, d):
    law = contact.RoughElastic(k, s, offset=s0)
    return law.force(d), law.stiffness(d), law.potential(d)


@jax.jit
def _rough_grads(k, s, s0, d):
    def f(k, s, s0, d):
        return contact.RoughElastic(k, s, offset=s0).force(d)

    return jax.grad(f, argnums=(0, 1, 2, 3))(k, s, s0, d), jax.grad(
        lambda d: contact.RoughElastic(k, s, offset=s0).potential(d)
    )(d)


@jax.jit
def _hertz(k, d):
    law = contact.HertzElastic(k)
    return law.force(d), law.stiffness(d), law.potential(d)


@SETTINGS
@given(stiffness, sigma, offset, delta, delta)
def test_rough_law_finite_nonnegative_monotone_and_lipschitz(k, s, s0, d1, d2):
    lo, hi = min(d1, d2), max(d1, d2)
    f_lo, k_lo, u_lo = (float(x) for x in _rough(k, s, s0, lo))
    f_hi, k_hi, u_hi = (float(x) for x in _rough(k, s, s0, hi))
    for x in (f_lo, k_lo, u_lo, f_hi, k_hi, u_hi):
        assert math.isfinite(x) and x >= 0.0
    # Monotone in δ (force, stiffness and energy), to round-off.
    tol = 1e-12 * max(f_hi, 1e-300)
    assert f_lo <= f_hi + tol
    assert k_lo <= k_hi * (1 + 1e-10) + 1e-300
    # Continuity through the onset: the force is convex for n ≥ 1, so its change is bounded by
    # the larger slope times the step (mean-value theorem); this holds across δ = 0 for Hertz.
    assert f_hi - f_lo <= k_hi * (hi - lo) * (1 + 1e-9) + 1e-12 * f_hi + 1e-300


@SETTINGS
@given(stiffness, sigma, offset, delta)
def test_gradients_finite_everywhere_and_energy_derivative_is_the_force(k, s, s0, d):
    grads, du = _rough_grads(k, s, s0, d)
    assert all(math.isfinite(float(g)) for g in grads)
    f, stiff, _ = _rough(k, s, s0, d)
    # dU/dδ = F_e and dF/dδ = the closed-form stiffness.
    assert math.isclose(float(du), float(f), rel_tol=1e-9, abs_tol=1e-9 * k * 1e-7**N)
    assert math.isclose(float(grads[3]), float(stiff), rel_tol=1e-7, abs_tol=1e-6 * k * 1e-6**0.5)


@SETTINGS
@given(stiffness, st.floats(1e-9, 1.25e-4), delta)
def test_roughness_adds_force_jensen_and_tends_to_hertz(k, s, d):
    """For convex `x_+^n` (n ≥ 1), Jensen: `E[(δ + σZ)_+^n] ≥ δ_+^n`. Upper bound from
    `|a_+^n − b_+^n| ≤ n max(a, b)_+^(n−1) |a − b|` and subadditivity of `x^(n−1)` (n ≤ 2):
    `F_rough − F_hertz ≤ K n σ (E|Z| δ_+^(n−1) + E|Z|^n σ^(n−1))` → 0 as σ → 0."""
    rough = float(_rough(k, s, 0.0, d)[0])
    hertz = float(_hertz(k, d)[0])
    e_abs_z = math.sqrt(2.0 / math.pi)
    e_abs_z_n = 2 ** (N / 2) * math.gamma((N + 1) / 2) / math.sqrt(math.pi)
    bound = k * N * s * (e_abs_z * max(d, 0.0) ** (N - 1) + e_abs_z_n * s ** (N - 1))
    assert rough >= hertz * (1 - 1e-12)
    assert rough - hertz <= bound * (1 + 1e-9) + 1e-12 * hertz


@SETTINGS
@given(stiffness, st.floats(1e-9, 1.25e-4), st.floats(8.0, 1e3))
def test_deep_contact_matches_the_taylor_series_of_the_gaussian_average(k, s, depth):
    """`E[(δ + σZ)^n]/δ^n = Σ C(n,2j) E[Z^2j] ε^2j = 1 + C(n,2) ε² + 3 C(n,4) ε⁴ + 15 C(n,6) ε⁶
    + …`, `ε = σ/δ` (δ ≥ 8σ, where the series' next term, 105 C(n,8) ε⁸ ≈ 0.32 ε⁸, bounds the
    rest)."""
    d = depth * s
    eps = 1.0 / depth
    ratio = float(_rough(k, s, 0.0, d)[0]) / (k * d**N)
    c2 = N * (N - 1) / 2
    c4 = c2 * (N - 2) * (N - 3) / 12
    c6 = c4 * (N - 4) * (N - 5) / 30
    series = 1 + c2 * eps**2 + 3 * c4 * eps**4 + 15 * c6 * eps**6
    assert abs(ratio - series) <= 1.0 * eps**8 + 1e-12


@SETTINGS
@given(stiffness, sigma, st.floats(0.0, 1e-4))
def test_offset_shifts_the_law_by_s0_sigma(k, s, d):
    """Clearance measured between peak tops (s0) = the mean-line law moved by s0 σ."""
    s0 = 3.0
    shifted = float(_rough(k, s, s0, d)[0])
    reference = float(_rough(k, s, 0.0, d - s0 * s)[0])
    assert math.isclose(shifted, reference, rel_tol=1e-12, abs_tol=1e-300)


@jax.jit
def _damped(k, s, c_e, d, dd, v_minus):
    elastic = contact.RoughElastic(k, s)
    out = []
    for cls in (
        contact.HuntCrossley,
        contact.LankaraniNikravesh,
        contact.Flores,
        contact.Gonthier,
        contact.HuGuo,
    ):
        law = cls(elastic=elastic, restitution=c_e)
        grads = jax.grad(law.force, argnums=(0, 1, 2))(d, dd, v_minus)
        out.append((law.force(d, dd, v_minus), law.chi(), *grads))
    return elastic.force(d), out


@SETTINGS
@given(stiffness, sigma, restitution, delta, rate, speed)
def test_damped_laws_nonnegative_finite_and_on_the_right_side_of_elastic(k, s, c_e, d, dd, vm):
    f_e, laws = _damped(k, s, c_e, d, dd, vm)
    f_e = float(f_e)
    for f, chi, *grads in laws:
        f, chi = float(f), float(chi)
        assert math.isfinite(f) and f >= 0.0
        assert all(math.isfinite(float(g)) for g in grads)
        assert chi >= 0.0
        # Approaching adds force, separating removes it; no tension.
        if dd >= 0:
            assert f >= f_e * (1 - 1e-12)
        else:
            assert f <= f_e * (1 + 1e-12)


@SETTINGS
@given(stiffness, sigma, delta, speed)
def test_damped_law_equals_elastic_at_rest_and_for_perfect_restitution(k, s, d, vm):
    f_e, laws = _damped(k, s, 1.0, d, 0.3, vm)
    for f, chi, *_ in laws:
        assert float(chi) == 0.0
        assert math.isclose(float(f), float(f_e), rel_tol=1e-14, abs_tol=1e-300)
    f_e, laws = _damped(k, s, 0.5, d, 0.0, vm)
    for f, *_ in laws:
        assert math.isclose(float(f), float(f_e), rel_tol=1e-14, abs_tol=1e-300)


@SETTINGS
@given(st.floats(1e-3, 1.0), st.floats(1e-3, 1.0))
def test_hysteresis_grows_as_restitution_falls(c1, c2):
    lo, hi = min(c1, c2), max(c1, c2)
    _, laws_lo = _damped(1e10, 0.0, lo, 1e-6, 0.1, 0.1)
    _, laws_hi = _damped(1e10, 0.0, hi, 1e-6, 0.1, 0.1)
    for (_, chi_lo, *_), (_, chi_hi, *_) in zip(laws_lo, laws_hi, strict=True):
        assert float(chi_lo) >= float(chi_hi) * (1 - 1e-12)


@jax.jit
def _friction(m, v, fn):
    laws = (
        contact.SmoothCoulomb(m),
        contact.SmoothCoulomb(m, shape="tanh"),
        contact.AmbrosioCoulomb(m),
        contact.AmbrosioCoulomb(m, transition="smoothstep"),
        contact.StribeckFriction(m, 0.8 * m, 1e-2),
    )
    return [
        (law.force(v, fn), law.force(-v, fn), *jax.grad(law.force, argnums=(0, 1))(v, fn))
        for law in laws
    ]


@SETTINGS
@given(mu, st.one_of(st.just(0.0), rate), st.floats(0.0, 1e9))
def test_friction_bounded_odd_opposes_sliding_with_finite_gradients(m, v, fn):
    for f, f_minus, *grads in _friction(m, v, fn):
        f, f_minus = float(f), float(f_minus)
        assert abs(f) <= m * fn * (1 + 1e-12)
        assert f == -f_minus
        assert f * v >= 0.0  # signed along +t with the sliding velocity; applied against it
        assert all(math.isfinite(float(g)) for g in grads)
    if v == 0.0:
        assert all(float(f) == 0.0 for f, *_ in _friction(m, v, fn))


@SETTINGS
@given(st.floats(1e-9, 1.25e-4), st.floats(1e-9, 1.25e-4))
def test_combined_roughness_is_a_norm_and_ra_round_trips(s1, s2):
    combined = float(contact.combine_sigma(s1, s2))
    assert max(s1, s2) <= combined <= s1 + s2
    assert math.isclose(float(contact.sigma_to_ra(contact.ra_to_sigma(s1))), s1, rel_tol=1e-14)


def test_exactly_zero_points_have_finite_gradients():
    """The special points of issue 8: δ = 0 (contact onset of Hertz), σ = 0, v_t = 0, v⁻ = 0."""
    for s in (0.0, 1e-6):
        grads, du = _rough_grads(1e10, s, 0.0, 0.0)
        assert all(math.isfinite(float(g)) for g in (*grads, du))
    _, laws = _damped(1e10, 0.0, 0.9, 0.0, 0.0, 0.0)
    for _, _, *grads in laws:
        assert all(math.isfinite(float(g)) for g in grads)
    for _, _, *grads in _friction(0.3, 0.0, 10.0):
        assert all(math.isfinite(float(g)) for g in grads)
    g = jax.grad(lambda x: jnp.sum(contact.combine_sigma(x, x)))(0.0)
    assert math.isfinite(float(g))
