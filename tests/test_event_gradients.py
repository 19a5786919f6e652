"""Derivatives of event times (`Scene.events`: located inside their step, differentiated by the
implicit-function theorem) against references that share no code with the package:

* slider_crank's first contact onset against the closed form of free flight from the centred
  start, and its derivative with respect to the clearance against central differences of the
  independent minimal-coordinate model (tests/independent/slider_crank_minimal.py: scipy,
  onset located as an event at rtol 1e-12);
* deploy_array's lock time (ideal joints) and its derivative with respect to the spring
  stiffness against central differences of the independent one-coordinate model
  (tests/independent/deploy_array_minimal.py, latch located by solve_ivp at rtol 1e-12).

Short horizons: each run ends just past its event."""

import copy
import json
import math

import jax.numpy as jnp
import numpy as np
import pytest
from independent.deploy_array_minimal import DATA_FILE, DeployArrayMinimal
from independent.slider_crank_minimal import SliderCrankMinimal

from jaxdeploy import fit
from jaxdeploy.scenes import DeployArray, SliderCrank


def _first_onset(params, t_end):
    """(t_on, dt_on/dc) of the package: forward mode through the default adaptive run."""
    scene = SliderCrank()
    value, grad = fit.parameter_gradient(
        scene, params, ["clearance"], lambda o: o["first_onset_time"], t_end, n_save=2,
        mode="forward",
    )  # fmt: skip
    return float(value), float(grad["clearance"])


def _free_flight_acceleration(p):
    """|ë(0)| of the eccentricity at the centred start (closed form). At t = 0 the journal is
    centred with the ideal mechanism's velocities, so ė(0) = 0; the slider feels no force out
    of contact (ẍ_s = 0) and the rod turns about the crank pin A under gravity alone:
    ë(0) = Ä + l (φ̈ u⊥ − φ̇² u), u = (1, 0), φ̇ = −r ω / l, Ä = −r ω² (1, 0),
    (I_r + m_r l²/4) φ̈ = −m_r g l/2. Hence e(t) = ë(0) t²/2 + O(t³) and the first onset of
    a clearance c is t_on = sqrt(2c/|ë(0)|) (1 + O(ω t_on)), dt_on/dc = t_on/(2c)."""
    r, ell, omega = p["crank_length"], p["rod_length"], p["crank_speed"]
    m_r, i_r, g = p["rod_mass"], p["rod_inertia"], p["gravity"]
    phi_ddot = -m_r * g * ell / 2 / (i_r + m_r * ell**2 / 4)
    ax = -r * omega**2 - ell * (r * omega / ell) ** 2
    return math.hypot(ax, ell * phi_ddot)


@pytest.mark.slow  # an independent check: forward mode through slider_crank's adaptive run
def test_first_onset_time_and_its_clearance_derivative_match_free_flight():
    """At c = 0.1 µm the first onset comes after 3.2 µs (ω t_on = 1.7e-3): the closed form's
    neglected O(ω t_on) is ~1e-3, so 5e-3 is its accuracy, not the package's."""
    scene = SliderCrank()
    p = scene.resolve_params({"clearance": 1e-7})
    t_free = math.sqrt(2 * 1e-7 / _free_flight_acceleration(p))
    t_on, dt_dc = _first_onset({"clearance": 1e-7}, 1.5 * t_free)
    assert t_on == pytest.approx(t_free, rel=5e-3)
    assert dt_dc == pytest.approx(t_free / (2 * 1e-7), rel=5e-3)


@pytest.mark.slow  # an independent check: the same program as the one above, and scipy runs
def test_first_onset_clearance_derivative_matches_the_independent_model():
    """At the scene's clearance (0.5 mm, onset at 0.227 ms, ω t_on = 0.12: far from the
    closed form's range), against central differences of the independent model at rtol 1e-12
    (h = 1e-4 c: truncation ~1e-8, round-off ~1e-9 relative). The package runs at the scene's
    default tolerance (rtol 1e-6): measured agreement 1e-6 relative; 1e-4 allows the
    tolerance's effect on the located onset."""
    c, h = 0.5e-3, 0.5e-7

    def onset(clearance):
        return SliderCrankMinimal({"clearance": clearance}).solve(3e-4).onsets[0]

    reference_time = onset(c)
    reference = (onset(c + h) - onset(c - h)) / (2 * h)
    t_on, dt_dc = _first_onset({}, 2.5e-4)
    assert t_on == pytest.approx(reference_time, rel=1e-6)
    assert dt_dc == pytest.approx(reference, rel=1e-4)


def _minimal_lock_time(stiffness):
    data = json.loads(DATA_FILE.read_text())
    data = copy.deepcopy(data)
    data["coil_spring"]["k"] = stiffness
    return DeployArrayMinimal(data).simulate(0.56, rtol=1e-12, atol=1e-12).lock_time


@pytest.mark.slow  # ~60 s CPU: one adaptive ideal-joint run to 0.56 s in forward mode
def test_ideal_lock_time_stiffness_derivative_matches_the_independent_model():
    """The ideal array's lock time and d t_L/d k against the one-coordinate model (latch
    located by solve_ivp; central differences at h = 1e-4 k, rtol 1e-12). The package runs at
    its default tolerance (Tsit5, rtol 1e-6)."""
    scene = DeployArray(ideal=True)
    k = scene.resolve_params()["spring_stiffness"]
    value, grad = fit.parameter_gradient(
        scene, {}, ["spring_stiffness"], lambda o: o["lock_time"], 0.56, n_save=2,
        mode="forward",
    )  # fmt: skip
    h = 1e-4 * k
    reference = (_minimal_lock_time(k + h) - _minimal_lock_time(k - h)) / (2 * h)
    assert float(value) == pytest.approx(_minimal_lock_time(k), rel=1e-6)
    assert float(grad["spring_stiffness"]) == pytest.approx(reference, rel=1e-4)
    assert np.isfinite(float(jnp.asarray(value)))


# Measured (forward mode, Tsit5 rtol 1e-8, 0.567 s, load 11-16): AD d t_L/d c = −143.005 s/m and
# d t_L/d c_e = −2.10797e-3 s against rerun differences −143.06 / −2.10756e-3 at h = 1e-5 and
# −143.015 / −2.10748e-3 at h = 3e-5 (4e-4 and 2e-4 apart); steps h ≥ 3e-4 change the impact
# count (12 + 6 impacts), smaller ones keep it. Before the clearance joint held v⁻ past a
# separation, AD was 1.4 % and 2.6 % off here.
LOCK_CONTROL = {"rtol": 1e-8, "atol": 1e-11}


@pytest.mark.slow  # an independent check: 194 CPU-s at load 13 (forward mode + 4 reruns)
def test_lock_time_clearance_and_restitution_derivatives_match_rerun_differences():
    """deploy_array with its clearance joints: the lock time's derivatives with respect to the
    root hinge's clearance and the restitution, forward mode through the located events and
    the contact episodes before the lock, against central differences of re-adapted runs at
    the same tight tolerance (h = 3e-5 relative: below the steps that change the impact count,
    above the tolerance's noise). Agreement measured 4e-4 and 2e-4; 2e-3 asserted."""
    scene = DeployArray()
    wrt = ["panel1_clearance", "restitution"]
    t_end = 0.567

    def outputs(o):
        return jnp.stack([o["lock_time"], o["panel1_impacts"], o["panel2_impacts"]])

    value, grad = fit.parameter_gradient(
        scene, {}, wrt, lambda o: o["lock_time"], t_end, n_save=2, control=LOCK_CONTROL,
        mode="forward",
    )  # fmt: skip
    assert 0.539 < float(value) < 0.541
    fd = fit.central_differences(
        scene, {}, wrt, outputs, t_end, 3e-5, n_save=2, control=LOCK_CONTROL, replay=False
    )
    for name in wrt:
        difference = np.asarray(fd[name])
        assert np.all(difference[1:] == 0), f"{name}: the impact count changed"
        assert float(grad[name]) == pytest.approx(float(difference[0]), rel=2e-3)
