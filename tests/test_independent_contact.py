"""The package's contact against references that share no code with it (issue 19 item 2):

* the `impact` scene with the rough (Greenwood–Williamson-averaged) law against the 1-DOF
  reference `tests/independent/impact_rough.py` (energy quadrature undamped, events-located
  `solve_ivp` with Lankarani–Nikravesh damping);
* friction on a case with a closed-form answer, built with the public mechanism API: a journal
  spinning in a fixed bearing under a constant load settles where tan α = μ (the friction
  circle) and spins down at μ W R_j cos α / J;
* the Hertz stiffness the slider_crank scene uses against the one the minimal-coordinate
  reference writes from Flores & Ambrósio (2004).
"""

import numpy as np
import pytest
from independent.crossings import level_crossings
from independent.impact_rough import (
    RoughWall,
    damped_impact,
    gaussian_moment,
    gaussian_moment_mpmath,
    tail_energy_fraction,
    undamped_impact,
)
from independent.package_runs import (
    IMPACT,
    IMPACT_T_END,
    IMPACT_TS,
    SPINNING,
    impact_run,
    return_to_centre,
    slider_crank_stiffness,
    spinning_journal,
)
from independent.slider_crank_minimal import SliderCrankMinimal

from jaxdeploy.scenes import get_scene

MASS, SPEED, STIFFNESS = IMPACT["mass"], IMPACT["speed"], IMPACT["stiffness"]
CLEARANCE, SIGMA = IMPACT["clearance"], IMPACT["sigma"]
TS = IMPACT_TS
# Tolerances that bring each solver's error below the checks: generalized-α is second order
# (at rtol 1e-10 its contact time is off by 1e-7 relative; 4451 steps vs 19748 at 1e-12).
RTOL = {"dopri8": 1e-10, "generalized_alpha": 1e-12}
# ~10 s each (mostly compilation): the Dopri8 runs in the default suite, generalized-α slow.
SOLVERS = [
    "dopri8",
    pytest.param("generalized_alpha", marks=pytest.mark.slow),
]


def _impact_run(damping, solver):
    rtol = RTOL[solver]
    return impact_run(damping, solver=solver, rtol=rtol, atol=1e-5 * rtol, dt_max=1e-6)


def test_impact_case_is_the_scenes():
    params = get_scene("impact").resolve_params({"sigma": SIGMA})
    assert (params["mass"], params["impact_speed"]) == (MASS, SPEED)
    assert (params["stiffness"], params["clearance"]) == (STIFFNESS, CLEARANCE)


def test_gaussian_moments_two_independent_quadratures():
    """QUADPACK with the (s − h)^n weight against mpmath at 30 digits, and against the
    values tabulated in the literature for F_1.5 (Greenwood & Williamson 1966, to 5 digits)."""
    for n in (1.5, 2.5):
        for h in (-11.0, -3.0, -1.0, 0.0, 0.5, 2.0, 3.0, 6.0):
            exact = float(gaussian_moment_mpmath(n, h))
            assert gaussian_moment(n, h) == pytest.approx(exact, rel=1e-12, abs=0.0)
    tabulated = {-1: 1.40460, 0: 0.43002, 1: 7.5668e-2, 2: 6.6482e-3, 3: 2.6397e-4}
    for h, value in tabulated.items():
        assert gaussian_moment(1.5, h) == pytest.approx(value, rel=5e-5)


@pytest.mark.parametrize("solver", SOLVERS)
def test_rough_undamped_impact_matches_energy_quadrature(solver):
    """Contact time between the crossings of δ = 0 and of δ = −3σ, δ_max (from the ODE
    reference's deepest point, which agrees with the quadrature to 1e-15), the whole path
    x(t), and the rebound speed (exactly v0)."""
    wall = RoughWall(STIFFNESS, SIGMA)
    levels = (0.0, -3.0 * SIGMA)
    delta_max, durations = undamped_impact(MASS, SPEED, CLEARANCE, wall, levels)
    ode = damped_impact(MASS, SPEED, CLEARANCE, wall, restitution=1.0)
    # The two ways of the reference agree (quadrature vs ODE).
    assert ode.max_penetration == pytest.approx(delta_max, rel=1e-12)
    assert ode.separation_time - ode.onset_time == pytest.approx(durations[levels[1]], rel=1e-12)
    hertz_max = (5.0 * MASS * SPEED**2 / (4.0 * STIFFNESS)) ** 0.4
    assert abs(delta_max / hertz_max - 1.0) > 3e-3  # roughness matters at this σ

    x, v = _impact_run("none", solver)
    for level in levels:
        t_in, t_out = level_crossings(TS, x, v, CLEARANCE + level)
        assert t_out - t_in == pytest.approx(durations[level], rel=1e-8), level
    t_back, speed = return_to_centre(x, v)
    assert speed == pytest.approx(SPEED, rel=1e-8)
    assert t_back == pytest.approx(ode.return_time, rel=1e-8)
    before = TS <= ode.return_time
    assert np.max(np.abs(x[before] - ode.sample(TS[before])[:, 0])) < 1e-7 * CLEARANCE


@pytest.mark.parametrize("solver", SOLVERS)
def test_rough_lankarani_nikravesh_impact_matches_ode_reference(solver):
    """Rebound speed, contact time (between the onset and separation at δ = −3σ) and x(t).

    The rough force has no true onset: below δ = −3σ the reference keeps the elastic tail
    undamped, and a different choice there (e.g. the package's) changes the energy by at
    most (1 + χ) U_e(−3σ); the rebound speed may therefore differ by up to that fraction of
    the impact energy, 4.9e-7 here, and no more."""
    wall = RoughWall(STIFFNESS, SIGMA)
    restitution = 0.9
    ref = damped_impact(MASS, SPEED, CLEARANCE, wall, restitution)
    chi = 0.75 * (1.0 - restitution**2)
    tail = (1.0 + chi) * tail_energy_fraction(MASS, SPEED, wall)
    assert 1e-7 < tail < 1e-6
    x, v = _impact_run("lankarani_nikravesh", solver)
    _, speed = return_to_centre(x, v)
    assert speed == pytest.approx(ref.rebound_speed, rel=tail)
    assert abs(ref.rebound_speed - restitution * SPEED) > 1e-3  # the law, not c_e itself
    t_in, t_out = level_crossings(TS, x, v, CLEARANCE - 3.0 * SIGMA)
    assert t_in == pytest.approx(ref.onset_time, rel=1e-8)
    assert t_out - t_in == pytest.approx(ref.separation_time - ref.onset_time, rel=tail)
    before = TS <= ref.separation_time
    # A speed difference ≤ tail · v0 held for the whole run bounds the path difference.
    assert np.max(np.abs(x[before] - ref.sample(TS[before])[:, 0])) < tail * SPEED * IMPACT_T_END


def test_spinning_journal_friction_circle_closed_form():
    """A journal (mass m, J = m R_j²/2) spinning at ω0 in a fixed bearing, loaded by its weight
    W = m g, with Coulomb friction μ (tanh-regularised, v_t = R_j ω ≫ v_s so the sign is
    saturated) and an undamped Hertz wall. Its equilibrium is on the wall at the angle α from
    the bottom, tan α = μ, on the side the friction drags it to (−x for ω > 0): there
    F_N = W cos α, F_T = μ F_N, and the friction moment about the journal's centre is
    −R_j F_T, so ω(t) = ω0 − μ W R_j cos α t / J exactly (the friction circle; e.g. Shigley,
    *Mechanical Engineering Design*, journal-bearing friction). A friction force applied at the
    wrong point, with the wrong sign or the wrong magnitude moves the journal off this point."""
    ts, q, v, centre, deceleration = spinning_journal(rtol=1e-10, atol=1e-13)
    omega0, radius, slip = SPINNING["omega0"], SPINNING["radius"], SPINNING["slip"]
    np.testing.assert_allclose(v[:, 2], omega0 - deceleration * ts, rtol=1e-12, atol=0)
    np.testing.assert_allclose(
        q[:, 2], omega0 * ts - 0.5 * deceleration * ts**2, rtol=0, atol=1e-12
    )
    assert np.max(np.abs(q[:, :2] - centre)) < 1e-15  # [m]; the load's static δ is ~1e-6 m
    assert radius * v[-1, 2] > 100 * slip  # still sliding: tanh(v_t/v_s) = 1 throughout


def test_slider_crank_stiffness_is_the_papers():
    """K = 4/(3(σ_i + σ_j)) sqrt(R_i R_j/(R_i − R_j)) (Flores & Ambrósio 2004), written in the
    reference, equals the stiffness the scene builds, for the default and another geometry."""
    for overrides in ({}, {"clearance": 0.1e-3, "journal_radius": 12e-3, "poisson_ratio": 0.25}):
        used = slider_crank_stiffness(overrides)
        assert used == pytest.approx(SliderCrankMinimal(overrides).K, rel=1e-14)
    assert SliderCrankMinimal().K == pytest.approx(6.6102e10, rel=1e-4)
