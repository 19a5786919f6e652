"""slider_crank against the independent minimal-coordinate reference (issue 19 item 3).

The reference (`tests/independent/slider_crank_minimal.py`: rod angle and slider position as
coordinates, Lagrange's equations, classical Lankarani–Nikravesh rule with every onset and
separation located by scipy events) shares no code and no modelling shortcut with the package
(absolute coordinates, constraint solves, a two-sided clearance joint, step-wise memory). Its
trajectories are stored in `tests/data/slider_crank_reference.npz` (`cd tests && python -m
independent.generate`; the file's `meta` says how converged they are).

Checks: the slider position x_s over the first 4 ms (1 µs grid), and over two revolutions the
number of impacts and their onset times (`independent.package_runs.slider_crank_run`).
"""

import json

import numpy as np
import pytest
from independent import generate
from independent.package_runs import TWO_REVOLUTIONS, slider_crank_run, slider_crank_scene
from independent.slider_crank_minimal import PARAMETERS

from jaxdeploy import StepControl

CASES = {"mu0": 0.0, "mu0.01": 0.01}


@pytest.fixture(scope="module")
def reference():
    with np.load(generate.PATH) as data:
        return {k: np.array(data[k]) for k in data.files}


def test_reference_fixture_is_converged(reference):
    """The stored runs agree with their check runs (DOP853 at 10× the tolerance, Radau) far
    below what the package is asked to reach, and on the saved grids the tests use."""
    meta = json.loads(str(reference["meta"]))
    for case in CASES:
        for check in meta["cases"][case]["checks"]:
            n_ref, n_check = check["n_onsets"]
            assert n_ref == n_check, check
            assert check["onsets_s"] < 1e-8 and check["x_s_4ms_m"] < 1e-12, check
        assert meta["cases"][case]["n_tensile_events"] == 0  # the max(0, ·) guard never acted
    assert reference["mu0_onsets"].size == 26 and reference["mu0.01_onsets"].size == 43
    np.testing.assert_array_equal(reference["fine_ts"], generate.FINE_TS)
    assert meta["t_end_s"] == pytest.approx(TWO_REVOLUTIONS, rel=1e-15)


def test_reference_case_is_the_scenes():
    """The reference's parameters are the scene's defaults (the friction case: μ, v_s)."""
    for case, mu in CASES.items():
        _, params = slider_crank_scene(mu)
        for name, value in generate.CASES[case]["params"].items():
            assert params[name] == value, name
        for name, value in PARAMETERS.items():
            if name not in generate.CASES[case]["params"]:
                assert params[name] == pytest.approx(value, rel=1e-15), name


def test_default_tolerance_within_3p5e7_m_over_4ms(reference):
    """The scene's default step control (rtol 1e-6, atol 1e-9, dt_max 0.1 ms) on the default
    solver (Tsit5 at this tolerance): x_s within 3.5e-7 m (0.07 % of c) of the reference over
    the first 4 ms (11 impacts)."""
    scene, _ = slider_crank_scene(0.0)
    _, x_s, _, _ = slider_crank_run(0.0, 4e-3, **scene.default_control)
    error = np.max(np.abs(x_s - reference["mu0_fine"][:, 1]))
    # Measured 1.73e-7 m at 938a945 (the bound was 1e-5 m, 58x that, from when generalized-α
    # was the default and reached 4.1e-6 m): 2x the measured error, so a change that makes the
    # default run twice as far from the reference fails here and not only in the slow set.
    assert error < 3.5e-7, error


TIGHT = {"rtol": 1e-10, "atol": 1e-13}
# μ = 0.01 on the default path (Dopri8) runs 10x tighter. At rtol 1e-10 its largest onset error
# (always the 42nd impact's) is a coin toss against 1e-7 s: 1.27e-7 s on main, and 5.9e-9,
# 1.1e-8, 1.6e-8, 1.6e-8, 4.4e-8, 7.4e-8 s when dt_max, atol or rtol alone is moved by 1e-4
# of itself; over the package's history 1.01e-7 (afafd97 .. 43d9876), 2.52e-7 (726575b),
# 1.27e-7 (b638cc7 .. main, bit-identical across the v⁻ hold 24d92c1/0625d72 and the XLA
# flag b2d3415). No modelling change moved it: a commit that changes round-off places the steps
# differently. Cause: each impact leaves a velocity error of the tolerance's size whose sign
# and size depend on where the steps fall (after the first impact, 2.6e-10 m/s against a
# rtol-1e-13 run; 2.9e-11 m/s with atol moved by 1e-4), and this case amplifies it ~10x every
# four impacts (the onset errors are one pattern, growing from ~1e-11 s at the 16th impact to
# its maximum at the 42nd, times a factor the step placement sets). At rtol 1e-11, atol 1e-14
# the same seven perturbations give 2.4e-9 … 1.7e-8 s (4.5k steps instead of 3.5k, ~2 CPU-s
# warm), at rtol 1e-12 1.3e-9 s: converging to the reference, whose own onsets are within
# ~6e-9 s (its 10x looser check run, the fixture's meta). The target stays 1e-7 s.
FRICTION_TIGHT = {"rtol": 1e-11, "atol": 1e-14}
# generalized-α at rtol 1e-10, atol 1e-13 used to stop advancing at t = 12.02 ms (the slider's
# dead centre, inside the 4 ms contact that begins at 11.745 ms): the index-3 step's velocities
# carried the round-off of Φ(q) = 0 amplified by γ' ~ 2/h, the contact's damping turned it into
# acceleration noise that the error estimate differences, and with |ẋ_s| → 0 (tolerance atol)
# no step size passed. Fixed by `GeneralizedAlpha.project_velocities` (its docstring).
#
# generalized-α is second order, so it is run at rtol 1e-12, atol 1e-15 here: at rtol 1e-10
# its onsets over two revolutions are off by up to 6.3e-7 s (μ = 0), at 1e-11 by 2.1e-7 s;
# at 1e-12 (measured on the code of 61e187c, below c56cdd5 that set this bound, whose run's
# own commit was rebased away; 585k steps, 54 CPU-s at load ~8) by 4.8e-8 s with x_s within
# 4.4e-10 m over 4 ms: the target is met for μ = 0 (docs/verification.md).
#
# μ = 0.01 at rtol 1e-12 (648k steps): all 43 impacts, but onsets off by up to 3.9e-5 s.
# Profiled per impact: the first 20 within 2e-8 s, then the error grows about tenfold every
# four impacts (2e-7 s at the 26th, 1e-6 s at the 29th, 4e-5 s at the 42nd). Every method sees
# this amplification in the friction case (Tsit5 at rtol 1e-10: 4e-9 s without friction,
# 2e-6 s with; docs/solver_by_tolerance.md); Dopri8 meets it (at rtol 1e-11: FRICTION_TIGHT)
# because its early onsets are ~1e-11 s off, several hundred times closer than generalized-α's
# at 1e-12. With
# μ = 0, each tenfold tightening gained generalized-α only a factor 3–4.4 (6.3e-7 → 2.1e-7
# → 4.8e-8 s), so reaching 1e-7 s here would take rtol of order 1e-16 or below, under
# float64's resolution (and ~10⁷ steps). The cause is the method's order against this case's
# sensitivity, not a defect: strict xfail, the target stays.
GENERALIZED_ALPHA_TIGHT = {"rtol": 1e-12, "atol": 1e-15}
GENERALIZED_ALPHA_FRICTION = pytest.mark.xfail(
    strict=True,
    raises=AssertionError,
    reason="μ = 0.01, generalized-α at rtol 1e-12: onsets off by up to 3.9e-5 s (second-order "
    "error amplified ~2000x over the last 20 impacts of the friction case)",
)


# The default path at the tight tolerance: the scene's `"auto"` runs Dopri8
# below rtol 1e-8 (jaxdeploy.solvers.resolve_solver; the crossover measured in
# docs/solver_by_tolerance.md). What it replaced: Tsit5 at rtol 1e-10, atol 1e-13 finds all 43
# impacts of μ = 0.01 but its onsets are off by 2e-7 to 2e-6 s depending on the step bound (its
# global error at this tolerance; within 1e-7 s at rtol 1e-12), and generalized-α (the default
# at rtol 1e-6) is second order (above). Tsit5 forced at 1e-10 still meets the frictionless case.
@pytest.mark.slow
@pytest.mark.parametrize(
    ("case", "solver"),
    [
        ("mu0", "default"),
        ("mu0.01", "default"),
        ("mu0", "tsit5"),
        ("mu0", "generalized_alpha"),
        pytest.param("mu0.01", "generalized_alpha", marks=GENERALIZED_ALPHA_FRICTION),
    ],
)
def test_tight_tolerance_matches_reference_over_two_revolutions(reference, case, solver):
    """At rtol 1e-10, atol 1e-13 (`solver="default"`: the scene's default step control with
    these tolerances, as `jaxdeploy simulate slider_crank --rtol 1e-10 --atol 1e-13` runs it;
    μ = 0.01 on it at rtol 1e-11, atol 1e-14 and generalized-α at rtol 1e-12, atol 1e-15, see
    above): x_s within 1e-8 m over the first 4 ms; over two revolutions the same number of
    impacts, each onset within 1e-7 s."""
    scene, _ = slider_crank_scene(CASES[case])
    if solver == "default":
        tight = FRICTION_TIGHT if CASES[case] else TIGHT
        control = scene.default_control.replace(**tight, max_steps=400_000)
    elif solver == "generalized_alpha":
        control = StepControl(solver, max_steps=2_000_000, **GENERALIZED_ALPHA_TIGHT)
    else:
        control = StepControl(solver, max_steps=400_000, **TIGHT)
    ts, x_s, found, _ = slider_crank_run(CASES[case], TWO_REVOLUTIONS, **control)
    first = ts <= generate.FINE_TS[-1] + 1e-12
    error = np.max(np.abs(x_s[first] - reference[f"{case}_fine"][:, 1]))
    assert error < 1e-8, error
    expected = reference[f"{case}_onsets"]
    assert found.size == expected.size, (found, expected)
    assert np.max(np.abs(found - expected)) < 1e-7, np.abs(found - expected)


@pytest.mark.slow
def test_tight_generalized_alpha_over_4ms(reference):
    """generalized-α at rtol 1e-10, atol 1e-13 over the first 4 ms (11 impacts): x_s within
    1e-8 m, the same onsets within 1e-7 s."""
    ts, x_s, found, _ = slider_crank_run(0.0, 4e-3, solver="generalized_alpha", **TIGHT)
    error = np.max(np.abs(x_s - reference["mu0_fine"][:, 1]))
    assert error < 1e-8, error
    expected = reference["mu0_onsets"][reference["mu0_onsets"] <= 4e-3]
    assert found.size == expected.size, (found, expected)
    assert np.max(np.abs(found - expected)) < 1e-7, np.abs(found - expected)


@pytest.mark.slow
def test_stored_fixture_is_what_the_generator_writes(reference):
    """Regenerating the frictionless run (~10 s) reproduces the stored arrays to the round-off
    of another machine's arithmetic, far below what a change of the generator's model or
    tolerance would move them."""
    _, solution = generate.run_case("mu0")
    fresh = generate.arrays(solution)
    # The run is not bit-reproducible across machines: scipy's DOP853 combines its stages with
    # BLAS, whose kernel OpenBLAS picks by CPU, and 26 impacts amplify the last-bit differences.
    # Measured with numpy/scipy 2.4.6/1.17.1 (the stored file's): OPENBLAS_CORETYPE set to each
    # of 8 kernels on one AMD EPYC gives 3 different runs (6976-6980 steps), the stored file
    # (6979 steps, made on another machine) a fourth; the largest difference between any two
    # is 5.7e-12 s in the onsets, 5.4e-13 m in x_s over 4 ms, 8.2e-11 m over two revolutions
    # (the bounds were 1e-12 s, 1e-13 m, 1e-10 m, which the same code met only on the machine
    # that wrote the file). Asserted: ~5x those. The generator's rtol 10x looser moves the
    # onsets by 1.5e-10 s and x_s over two revolutions by 2.2e-9 m (the file's meta), 5x the
    # bounds; its x_s over 4 ms only by 1.2e-13 m, below round-off: that column guards the model.
    np.testing.assert_allclose(fresh["onsets"], reference["mu0_onsets"], rtol=0, atol=3e-11)
    np.testing.assert_allclose(fresh["fine"], reference["mu0_fine"], rtol=0, atol=2e-12)
    np.testing.assert_allclose(fresh["coarse"], reference["mu0_coarse"], rtol=0, atol=4e-10)


def test_numpy_peer_with_the_classical_rule_matches_reference(reference):
    """The benchmark's numpy peer (absolute coordinates, Baumgarte-stabilised index-1 system,
    `benchmarks.peers`) with its default classical rule and the minimal-coordinate
    reference are two formulations of one model: x_s agrees to 1e-12 m over the first 2 ms
    (five impacts; measured 5e-14 m)."""
    from benchmarks.peers import SliderCrankNumpy

    scene, params = slider_crank_scene(0.0)
    state = scene.initial_state(params, scene.build(params))
    ts = generate.FINE_TS[generate.FINE_TS <= 2e-3 + 1e-12]
    peer = SliderCrankNumpy(params).solve(state, ts[-1], ts, "DOP853", 1e-12, 1e-14)
    assert peer.ok, peer.message
    kinds = [kind for _, kind, _ in peer.events]
    assert set(kinds) == {"onset", "separation"}  # no peak events with the classical rule
    onsets = [t for t, kind, _ in peer.events if kind == "onset"]
    np.testing.assert_allclose(onsets, reference["mu0_onsets"][: len(onsets)], rtol=0, atol=1e-12)
    error = np.max(np.abs(peer.ys[:, 6] - reference["mu0_fine"][: ts.size, 1]))
    assert error < 1e-12, error
