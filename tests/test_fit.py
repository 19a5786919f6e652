"""Identification: `jaxdeploy fit` recovers known parameters within its reported standard
errors; the Gauss–Newton covariance equals the closed form for a linear model; a parameter the
data cannot see is reported as not identified; malformed data files are refused, naming the
problem."""

import json
import math

import numpy as np
import pytest

from jaxdeploy.cli import main
from jaxdeploy.fit import (
    FitParameter,
    FitResult,
    MeasurementError,
    Measurements,
    ResidualSpec,
    fit,
    levenberg_marquardt,
    load_measurements,
    make_parameters,
    synthesize,
)
from jaxdeploy.fit._fit import AT_BOUND, ZMAX, _curvature, latin_hypercube_starts
from jaxdeploy.fit._residuals import Comparison
from jaxdeploy.scenes import Impact, Pendulum


@pytest.mark.slow  # 27 s of the default suite at 844cb65 (2 cores): kept out of it
def test_cli_fit_recovers_impact_parameters_within_reported_errors(tmp_path, capsys):
    """Synthetic journal position and acceleration through a damped impact (1 % noise);
    restitution and contact stiffness started far off are recovered within 3 standard
    errors, and those errors are small."""
    scene = Impact(damping="lankarani_nikravesh")
    truth = {"restitution": 0.7, "stiffness": 1e10}
    data = synthesize(
        scene, truth, np.linspace(0.0, 6e-4, 121), ["journal_x", "journal_ax"], seed=3
    )
    path = tmp_path / "impact.csv"
    data.save(str(path))
    out = tmp_path / "fit"
    argv = [
        "fit", str(path), "--scene", "impact", "--scene-option", "damping=lankarani_nikravesh",
        "--params", "restitution=0.4:0.05:0.99", "stiffness=2e10:1e8:1e12", "--out", str(out),
    ]  # fmt: skip
    assert main(argv) == 0
    report = json.loads((out / "fit.json").read_text())
    for name, value in truth.items():
        est, se = report["estimates"][name], report["standard_errors"][name]
        assert 0 < se < 0.05 * value
        assert abs(est - value) < 3 * se, (name, est, se)
    assert report["converged"] and report["noise"] == "given"
    assert 0.7 < report["reduced_chi2"] < 1.3  # residuals at the optimum are the noise
    assert report["params"]["restitution"] == report["estimates"]["restitution"]
    assert "jax" in report["versions"] and "seed" in report
    for name in ("history.csv", "fit.npz", "fit_journal_ax.png", "loss_history.png"):
        assert (out / name).exists()
    history = (out / "history.csv").read_text().splitlines()
    assert history[0].startswith("stage,evaluation,cost")
    costs = [float(row.split(",")[2]) for row in history[1:] if row.split(",")[3] == "1"]
    assert costs[-1] < 1e-2 * costs[0]
    assert "stage 0 eval" in capsys.readouterr().err  # progress lines
    # No silent overwrite.
    assert main(argv) == 2
    assert "--overwrite" in capsys.readouterr().err


def test_covariance_is_the_linear_least_squares_closed_form():
    """For r = (X θ − y)/σ the estimate is the least-squares solution and the covariance
    σ² (XᵀX)⁻¹, whatever the bounded reparametrisation θ(z) used inside."""
    rng = np.random.default_rng(0)
    x = np.column_stack([np.ones(40), np.linspace(0, 1, 40), np.linspace(0, 1, 40) ** 2])
    theta_true = np.array([2.0, -1.0, 0.5])
    sigma = 0.05
    y = x @ theta_true + sigma * rng.standard_normal(40)
    params = [FitParameter("a", 1.0, 0.1, 10.0), FitParameter("b", 0.0, -5.0, 5.0),
              FitParameter("c", 0.2, -3.0, 3.0)]  # fmt: skip

    def model(z):
        theta = np.array([float(p.to_physical(zk)) for p, zk in zip(params, z, strict=True)])
        dtheta = np.array([p.dphysical_dz(zk) for p, zk in zip(params, z, strict=True)])
        return (x @ theta - y) / sigma, x * dtheta / sigma, None, True

    z0 = np.array([p.to_internal(p.guess) for p in params])
    z, r, jac, _, info = levenberg_marquardt(model, z0, max_iterations=100, ftol=1e-14)
    theta, se, corr, cov, *_ = _curvature(params, z, r, jac, noise_known=True)
    np.testing.assert_allclose(theta, np.linalg.lstsq(x, y, rcond=None)[0], rtol=1e-7)
    expected = sigma**2 * np.linalg.inv(x.T @ x)
    np.testing.assert_allclose(cov, expected, rtol=1e-6)
    expected_corr = expected[0, 1] / np.sqrt(expected[0, 0] * expected[1, 1])
    np.testing.assert_allclose(corr[0, 1], expected_corr, rtol=1e-6)
    assert info["converged"]


def test_a_parameter_the_motion_does_not_depend_on_is_reported_not_identified():
    """A pendulum's mass does not change its motion: the fit finds the length and reports the
    mass's standard error as unbounded (noise level estimated from the residuals)."""
    scene = Pendulum()
    truth = {"length": 0.8, "initial_angle": -0.6}
    data = synthesize(scene, truth, np.linspace(0, 1.0, 101), ["rod_theta"], seed=5)
    data = Measurements(data.t, data.channels, {}, "pendulum")  # noise not given
    result = fit(scene, data, ["length=1.2:0.1:5", "mass=2:0.1:10"], fixed=truth)
    assert result.estimates["length"] == pytest.approx(
        0.8, rel=3 * result.relative_errors()["length"]
    )
    assert result.relative_errors()["length"] < 0.01
    assert result.not_identified() == ["mass"]
    assert (
        not math.isfinite(result.standard_errors["mass"]) or result.relative_errors()["mass"] > 10
    )
    assert result.report()["noise"] == "estimated from the residuals"
    # Its correlation with the length is undefined (NaN), not a confounded pair.
    assert math.isnan(result.correlation[0, 1]) and result.confounded_pairs() == []
    assert result.flags() == ["mass is not identified (std. error > 50% of the value)"]


def test_block_residuals_average_in_noise_units():
    t = np.linspace(0, 1, 11)
    data = Measurements(t, {"y": t**2}, {"y": 0.1})
    cmp_ = Comparison(data, ResidualSpec("block", windows=((0.0, 0.55),), block=0.2))
    # samples 0..5 (t <= 0.55) in blocks of 0.2 s: [0, .1], [.2, .3], [.4, .5]
    np.testing.assert_array_equal(cmp_.counts, [2, 2, 2])
    assert cmp_.n_save == 6 and cmp_.t_end == pytest.approx(0.5)
    r = np.asarray(cmp_.residuals({"y": t[:6] ** 2 + 0.3}))
    np.testing.assert_allclose(r, 0.3 / (0.1 / np.sqrt(2)))


def test_measurement_files_round_trip(tmp_path):
    data = Measurements(np.linspace(0, 1, 5), {"a": np.arange(5.0), "b": -np.arange(5.0)},
                        {"a": 0.5})  # fmt: skip
    for ext in ("csv", "npz"):
        path = str(tmp_path / f"m.{ext}")
        data.save(path)
        back = load_measurements(path)
        np.testing.assert_array_equal(back.t, data.t)
        np.testing.assert_array_equal(back.channels["b"], data.channels["b"])
        assert back.noise == {"a": 0.5}


@pytest.mark.parametrize(
    "text, message",
    [
        ("x,y\n0,1\n1,2\n", "no time column"),
        ("t,y\n0,1\n0,2\n", "strictly increasing"),
        ("t,y\n0,1\n1,nan\n", "column 'y' row 1"),
        ("t,y\n0,1\n1,2,3\n", "line 3 has 3 values"),
        ("t,y\n0,1\n1,abc\n", "'abc' is not a number"),
        ("t,y\n", "no data rows"),
        ("t\n0\n1\n", "no measured channel"),
        ("# sigma_y = -1\nt,y\n0,1\n1,2\n", "sigma_y = -1.0 is invalid"),
        ("# sigma_z = 1\nt,y\n0,1\n1,2\n", "noise level given for 'z'"),
        ("t,y,y\n0,1,1\n1,2,2\n", "'y' appears twice"),
        ("t,y\n0,1\n", "at least 2 samples"),
    ],
)
def test_malformed_csv_is_refused_naming_the_problem(tmp_path, text, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(MeasurementError, match=message):
        load_measurements(str(path))


def test_malformed_files_and_specs_are_refused(tmp_path, capsys):
    with pytest.raises(MeasurementError, match="no such file"):
        load_measurements(str(tmp_path / "missing.csv"))
    (tmp_path / "m.txt").write_text("t,y\n")
    with pytest.raises(MeasurementError, match="unknown format '.txt'"):
        load_measurements(str(tmp_path / "m.txt"))
    (tmp_path / "broken.npz").write_bytes(b"not a zip")
    with pytest.raises(MeasurementError, match="not a readable npz"):
        load_measurements(str(tmp_path / "broken.npz"))
    np.savez(tmp_path / "s.npz", t=[0.0, 1.0], y=np.array(["a", "b"]))
    with pytest.raises(MeasurementError, match="'y' is not numeric"):
        load_measurements(str(tmp_path / "s.npz"))
    scene = Impact(damping="lankarani_nikravesh")  # restitution counts (not with "none")
    with pytest.raises(ValueError, match="unknown parameter 'stifness'"):
        make_parameters(scene, ["stifness=1e10"])
    with pytest.raises(ValueError, match=r"restitution = 1.5 \(initial guess\) is invalid"):
        make_parameters(scene, ["restitution=1.5:0.1:0.99"])
    with pytest.raises(ValueError, match=r"must lie in \[0, 1\]"):
        make_parameters(scene, ["restitution=0.5:0.1:2"])
    with pytest.raises(ValueError, match="guess 'x' is not a number"):
        make_parameters(scene, ["restitution=x"])
    # Through the CLI: a channel the scene does not have, and a bad file, exit 2 with reasons.
    data = Measurements(np.linspace(0, 1e-4, 5), {"journal_q": np.zeros(5) + 1.0})
    data.save(str(tmp_path / "d.csv"))
    code = main(["fit", str(tmp_path / "d.csv"), "--scene", "impact", "--params", "stiffness",
                 "--out", str(tmp_path / "o"), "--quiet"])  # fmt: skip
    assert code == 2
    err = capsys.readouterr().err
    assert "channel 'journal_q' is not an output of scene 'impact'" in err and "journal_x" in err
    code = main(["fit", str(tmp_path / "m.txt"), "--scene", "impact", "--params", "stiffness",
                 "--out", str(tmp_path / "o2")])  # fmt: skip
    assert code == 2 and "unknown format" in capsys.readouterr().err


def test_latin_hypercube_starts_fill_every_stratum_within_the_bounds():
    params = [FitParameter("a", 1.0, 0.1, 10.0), FitParameter("b", 0.0, -5.0, 5.0)]
    z = latin_hypercube_starts(params, 16, seed=1)
    s = 1.0 / (1.0 + np.exp(-z))
    for column in s.T:  # one point in each of the 16 strata of every coordinate
        assert sorted(np.floor(column * 16).astype(int)) == list(range(16))
    theta = np.array([[float(p.to_physical(zk)) for p, zk in zip(params, row, strict=True)]
                      for row in z])  # fmt: skip
    assert np.all((theta[:, 0] > 0.1) & (theta[:, 0] < 10)) and np.all(np.abs(theta[:, 1]) < 5)


def test_multistart_escapes_the_local_minimum_a_far_guess_falls_into():
    """A pendulum observed over several swings: from a length 4× too long, LM alone locks onto
    a wrong phase (a local minimum); with a batch of Latin-hypercube starts first it finds the
    true length within its reported error."""
    scene = Pendulum()
    truth = {"length": 0.8, "initial_angle": -0.6}
    data = synthesize(scene, truth, np.linspace(0, 4.0, 201), ["rod_theta"], seed=7)
    spec = ["length=3.2:0.1:5"]
    alone = fit(scene, data, spec, fixed=truth, max_iterations=20)
    assert abs(alone.estimates["length"] - 0.8) > 0.05  # the landscape is rugged here
    result = fit(scene, data, spec, fixed=truth, max_iterations=20, starts=12, seed=0)
    multistart = result.stages[0]
    assert multistart["spec"]["kind"] == "multistart"
    assert multistart["cost"] < multistart["guess_cost"]
    se = result.standard_errors["length"]
    assert abs(result.estimates["length"] - 0.8) < 3 * se and se < 0.01
    assert 0.5 < result.reduced_chi2 < 1.5


def test_a_parameter_driven_onto_its_bound_gets_an_infinite_error_not_a_crash():
    """y = a x with the truth a = 2 outside the bounds (0.1, 1.5): LM drives a onto 1.5, where
    the bounded map's dθ/dz vanishes; the curvature then reports it as not determined."""
    x = np.linspace(0, 1, 30)
    y = 2.0 * x
    params = [FitParameter("a", 1.0, 0.1, 1.5), FitParameter("b", 0.0, -1.0, 1.0)]

    def model(z):
        theta = np.array([float(p.to_physical(zk)) for p, zk in zip(params, z, strict=True)])
        dtheta = np.array([p.dphysical_dz(zk) for p, zk in zip(params, z, strict=True)])
        design = np.column_stack([x, np.ones_like(x)])
        return (design @ theta - y) / 0.01, design * dtheta / 0.01, None, True

    z0 = np.array([p.to_internal(p.guess) for p in params])
    z, r, jac, _, _ = levenberg_marquardt(model, z0, max_iterations=200)
    z[0] = 800.0  # as far as LM gets it: the logistic map is flat to roundoff
    theta, se, *_ = _curvature(params, z, r, jac, noise_known=True)
    assert theta[0] == pytest.approx(1.5) and params[0].dphysical_dz(z[0]) == 0.0
    assert se[0] == np.inf and np.isfinite(se[1])
    result = _result_from_curvature(params, z, r, jac)
    assert result.at_bound == ["a"] and result.confounded_pairs() == []
    assert result.unresolved_combinations() == []
    assert result.flags() == ["a is at its bound (the data push it beyond)"]
    # With LM's limit on the internal coordinate (as in `fit`) a stops near the limit, is
    # reported at its bound, and keeps its (finite) column: b is then fitted given a = 1.5.
    z, r, jac, _, _ = levenberg_marquardt(model, z0, max_iterations=200, zmax=ZMAX)
    assert AT_BOUND <= z[0] <= ZMAX
    theta, se, _, _, _, _, details = _curvature(params, z, r, jac, noise_known=True)
    assert details["at_bound"] == ["a"] and np.all(np.isfinite(se))
    assert theta[0] == pytest.approx(1.5, rel=1e-6)


def _result_from_curvature(params, z, r, jac):
    theta, se, corr, cov, s, chi2, details = _curvature(params, z, r, jac, noise_known=True)
    names = [p.name for p in params]
    return FitResult(
        parameters=params, estimates=dict(zip(names, theta, strict=True)),
        standard_errors=dict(zip(names, se, strict=True)),
        correlation=corr, covariance=cov, singular_values=s, chi2=chi2, n_residuals=r.size,
        noise_known=True, iterations=0, evaluations=0, converged=True, message="",
        history=[], wall_time=0.0, comparison=None, model_initial={}, model_final={}, **details,
    )  # fmt: skip


def test_a_product_of_two_parameters_is_reported_as_the_unresolved_combination():
    """y = a b x (only the product is seen; like E and ν in E*): both get infinite errors,
    their NaN correlation is not reported as a confounded pair, and the report names the
    unseen direction ln a − ln b (unit vector ±(1, −1)/√2) with the third parameter, which
    is determined, left out of it."""
    x = np.linspace(0, 1, 30)
    params = [FitParameter("a", 1.0, 0.1, 10.0), FitParameter("b", 2.0, 0.1, 10.0),
              FitParameter("c", 0.5, -2.0, 2.0)]  # fmt: skip
    theta = np.array([1.5, 3.0, 0.3])
    z = np.array([p.to_internal(v) for p, v in zip(params, theta, strict=True)])
    dtheta = np.array([p.dphysical_dz(zk) for p, zk in zip(params, z, strict=True)])
    jac = np.column_stack([theta[1] * x, theta[0] * x, np.ones_like(x)]) * dtheta / 0.01
    r = 0.01 * np.sin(np.arange(30.0))
    result = _result_from_curvature(params, z, r, jac)
    assert np.isinf(result.standard_errors["a"]) and np.isinf(result.standard_errors["b"])
    assert np.isfinite(result.standard_errors["c"])
    assert result.confounded_pairs() == [] and result.at_bound == []
    (combo,) = result.unresolved_combinations()
    assert set(combo) == {"a", "b"}
    assert abs(combo["a"]) == pytest.approx(2**-0.5) and combo["a"] == pytest.approx(-combo["b"])
    flags = result.flags()
    assert flags[:2] == [f"{n} is not identified (std. error > 50% of the value)" for n in "ab"]
    assert flags[2].startswith("only a combination is unresolved") and len(flags) == 3
    assert "nan" not in json.dumps(result.report()["confounded_pairs"]).lower()


def test_smooth_residuals_are_in_noise_units_and_see_a_shifted_spike_that_blocks_miss():
    """Gaussian-smoothed residuals of pure white noise have unit variance (the scale
    σ √(Σ w²) is right); and for a spike 10 samples wide shifted by δ, the block loss is flat
    in δ while the spike stays inside one block (no gradient to follow), whereas the smoothed
    loss grows strictly with δ over the kernel width."""
    rng = np.random.default_rng(4)
    t = np.linspace(0.0, 1.0, 20001)
    noise = Measurements(t, {"y": rng.standard_normal(t.size)}, {"y": 1.0})
    smooth = Comparison(noise, ResidualSpec("smooth", width=0.004))
    r = smooth.residuals_np({"y": np.zeros_like(t)})
    assert r.size == smooth.size > 200
    assert np.mean(r**2) == pytest.approx(1.0, abs=0.15)

    def spike(t0):
        return np.exp(-0.5 * ((t - t0) / 2.5e-4) ** 2)

    data = Measurements(t, {"y": spike(0.5125)}, {"y": 0.01})
    block = Comparison(data, ResidualSpec("block", block=0.025))  # spike inside [0.5, 0.525)
    smooth = Comparison(data, ResidualSpec("smooth", width=0.02))
    shifts = np.linspace(0.0, 0.008, 9)
    block_loss = [np.sum(block.residuals_np({"y": spike(0.5125 + d)}) ** 2) for d in shifts]
    smooth_loss = [np.sum(smooth.residuals_np({"y": spike(0.5125 + d)}) ** 2) for d in shifts]
    assert np.all(np.diff(smooth_loss) > 0) and smooth_loss[-1] > 100
    assert max(block_loss) < 1e-12 * smooth_loss[-1]  # flat: the block cannot tell


@pytest.mark.parametrize("kind", ["trajectory", "block", "smooth"])
def test_residual_jacobian_is_the_residual_map_applied_to_the_channel_jacobian(kind):
    """Residuals are linear in the channel samples: the numpy Jacobian from the channels'
    Jacobian equals jax.jacfwd of the (JAX) residual function."""
    import jax

    t = np.linspace(0.0, 1.0, 101)
    rng = np.random.default_rng(1)
    data = Measurements(t, {"a": rng.standard_normal(101), "b": t}, {"a": 0.3, "b": 0.1})
    spec = ResidualSpec(kind, windows=((0.1, 0.8),), block=0.1, width=0.1)
    cmp_ = Comparison(data, spec)
    base = {n: rng.standard_normal(cmp_.n_save) for n in "ab"}
    dir_ = {n: rng.standard_normal((cmp_.n_save, 3)) for n in "ab"}

    def residuals(z):
        return cmp_.residuals({n: base[n] + dir_[n] @ z for n in "ab"})

    expected = np.asarray(jax.jacfwd(residuals)(np.zeros(3)))
    np.testing.assert_allclose(cmp_.residual_jacobian(dir_), expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(
        cmp_.residuals_np(base), np.asarray(residuals(np.zeros(3))), rtol=1e-12
    )


def test_widths_give_smooth_stages_ending_with_independent_residuals():
    from argparse import Namespace

    from jaxdeploy.commands.fit import _stages

    data = Measurements(np.linspace(0, 0.1, 11), {"y": np.ones(11)}, {"y": 1.0})
    args = Namespace(window=[], loss="trajectory", block=None, width=None,
                     widths="0.004,0.001", horizons="0.05,0.1")  # fmt: skip
    stages = _stages(args, data)
    assert [(s.kind, s.width, s.windows[0][1]) for s in stages] == [
        ("smooth", 0.004, 0.05), ("smooth", 0.001, 0.05), ("trajectory", None, 0.05),
        ("smooth", 0.004, 0.1), ("smooth", 0.001, 0.1), ("trajectory", None, 0.1),
    ]  # fmt: skip
    for bad, message in [(dict(widths="0.001,0.004"), "decrease"),
                         (dict(loss="smooth", width=0.01), "independent residuals")]:  # fmt: skip
        with pytest.raises(ValueError, match=message):
            _stages(Namespace(**{**vars(args), **bad}), data)


@pytest.mark.slow  # 18 s of the default suite at 844cb65 (2 cores): kept out of it
def test_continuation_in_smoothing_width_finds_an_impact_the_guess_misses():
    """The journal's acceleration is a spike while it touches the bearing (from t = c/v0).
    With the clearance guessed 4× too large the model's spike lies after the data's: the
    pointwise loss is flat in c there and LM stays far off; smoothing over 0.8, then 0.2,
    then 0.05 ms before the pointwise stage finds c within its reported error."""
    scene = Impact(damping="lankarani_nikravesh")
    truth = scene.resolve_params({"clearance": 1e-4, "restitution": 0.7})
    control = {"rtol": None, "atol": None, "dt_max": None, "dt": 1e-6}
    ts = np.linspace(0.0, 1.2e-3, 601)
    data = synthesize(scene, truth, ts, ["journal_ax"], seed=11, control=control)
    spec = ["clearance=4e-4:2e-5:1e-3"]
    alone = fit(scene, data, spec, fixed=truth, control=control, max_iterations=15)
    assert abs(alone.estimates["clearance"] - 1e-4) > 0.5e-4
    stages = [ResidualSpec("smooth", width=w) for w in (8e-4, 2e-4, 5e-5)] + [ResidualSpec()]
    result = fit(scene, data, spec, fixed=truth, control=control, residuals=stages,
                 max_iterations=15)  # fmt: skip
    se = result.standard_errors["clearance"]
    assert abs(result.estimates["clearance"] - 1e-4) < 3 * se < 0.03e-4
    assert 0.7 < result.reduced_chi2 < 1.3
    assert [st["spec"]["kind"] for st in result.stages] == ["smooth"] * 3 + ["trajectory"]


@pytest.mark.slow  # 538 CPU-s at load 4-18 (2 cores): over the 5 CPU-min target
def test_cli_fit_recovers_deploy_array_contact_parameters(tmp_path):
    """The worked identification (experiments/identification.py, docs/identification.md) cut
    to what a test needs: c, Ra, c_e and μ of the root hinge from synthetic data (1 % noise on
    the tip accelerations and the angle, another noise draw), each within 3 reported standard
    errors of the truth. The worked example fits 30 ms (about ten impacts) from guesses 50 %
    off through Latin-hypercube starts and four smoothing widths (over 100 model evaluations
    with their forward-mode Jacobians: more than 45 min here); this test fits the first 9 ms
    (the impacts at 2.6 and 7.4 ms) from guesses 3–10 % off (c_e 3 %, c 5 %, Ra and μ 10 %:
    inside the basins of docs/identification.md's loss landscape), through one smoothing
    width. It can fail: the guesses, and values 5 % off the truth, lie far outside 3 reported
    standard errors of the estimates, so a fit that stays near its guess, or recovers a wrong
    value, does not pass."""
    from jaxdeploy.scenes import DeployArray

    scene = DeployArray(clearance_joints={"J1": "panel1"})
    truth = scene.resolve_params()
    control = {"rtol": None, "atol": None, "dt_max": None, "dt": 1e-5}
    channels = ["panel1_tip_ax", "panel1_tip_ay", "panel2_tip_ax", "panel2_tip_ay", "alpha"]
    data = synthesize(scene, truth, np.linspace(0.0, 0.009, 451), channels, seed=7,
                      control=control)  # fmt: skip
    data.save(str(tmp_path / "data.npz"))
    names = ("panel1_clearance", "panel1_ra", "restitution", "friction_coefficient")
    factors = dict(zip(names, (1.05, 0.9, 0.97, 1.1), strict=True))
    guess = {name: truth[name] * factors[name] for name in names}
    bounds = {"panel1_clearance": "5e-6:5e-4", "panel1_ra": "1e-7:1e-5",
              "restitution": "0.05:0.99", "friction_coefficient": "0.001:0.5"}  # fmt: skip
    out = tmp_path / "fit"
    argv = [
        "fit", str(tmp_path / "data.npz"), "--scene", "deploy_array",
        "--scene-option", 'clearance_joints={"J1": "panel1"}', "--dt", "1e-5",
        "--widths", "0.001", "--max-iterations", "15", "--out", str(out), "--quiet",
        "--params", *(f"{n}={guess[n]!r}:{bounds[n]}" for n in names),
    ]  # fmt: skip
    assert main(argv) in (0, 4)  # 4: a stage stopped at --max-iterations
    report = json.loads((out / "fit.json").read_text())
    for name in names:
        est, se = report["estimates"][name], report["standard_errors"][name]
        assert 0 < se < 0.05 * truth[name]
        assert abs(est - truth[name]) < 3 * se, (name, est, se)
        for wrong in (guess[name], 0.95 * truth[name], 1.05 * truth[name]):
            assert abs(est - wrong) > 3 * se, (name, wrong, est, se)
    assert 0.8 < report["reduced_chi2"] < 1.2
    assert report["not_identified"] == [] and report["adequate"]


def test_the_check_at_a_tighter_tolerance_keeps_the_method_and_compiles_nothing():
    """`_schedule.tighter`: rtol and atol 10x smaller with the method resolved at the looser
    rtol ("auto" takes Tsit5 at rtol 1e-8, Dopri8 below it), so the check's run is the
    model's compiled program with other data: the call at the tighter tolerance traces
    nothing, and gives what a new model, compiled for that control alone, gives. Without
    the method kept the tighter control would resolve to Dopri8 (asserted first), a second
    program."""
    import threading

    import jax

    from jaxdeploy.fit._fit import Model
    from jaxdeploy.fit._schedule import _scaled, tighter
    from jaxdeploy.solvers import AUTO_TIGHT_RTOL

    scene = Impact(damping="lankarani_nikravesh")
    base = scene.resolve_params({})
    params = make_parameters(scene, ["restitution=0.6:0.05:0.99"], scene.resolve_params({}))
    ts = np.linspace(0.0, 6e-4, 31)
    control = {"solver": "auto", "rtol": AUTO_TIGHT_RTOL, "atol": 1e-12}

    def model():
        return Model(scene, params, base, ["journal_x"], ts, control, {})

    compiled, fresh = model(), model()
    tight = tighter(compiled.control)
    assert _scaled(compiled.control, 0.1).resolved_solver() != compiled.control.resolved_solver()
    assert tight.resolved_solver() == compiled.control.resolved_solver() == "tsit5"
    assert (tight.rtol, tight.atol) == pytest.approx((AUTO_TIGHT_RTOL / 10, 1e-13))
    z = np.array([0.3])
    compiled(z)  # the model's own program, traced and compiled here
    here, traces = threading.current_thread(), []

    def listener(event, _seconds, **kwargs):
        # The model's program (`_model_program.jacobian`), traced in this thread: a
        # primitive's first op-by-op dispatch in the process is an event of its own.
        if (
            event == "/jax/core/compile/jaxpr_trace_duration"
            and kwargs.get("fun_name") == "jacobian"
            and threading.current_thread() is here
        ):
            traces.append(event)

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        channels, jac, ok = compiled(z, control=tight)
    finally:  # only this listener: other tests' stay registered
        jax.monitoring.unregister_event_duration_listener(listener)
    assert traces == []
    jax.clear_caches()  # the same description's program, traced and compiled anew
    expected = fresh(z, control=tight)
    assert ok and expected[2]
    np.testing.assert_array_equal(channels["journal_x"], expected[0]["journal_x"])
    np.testing.assert_array_equal(jac["journal_x"], expected[1]["journal_x"])
