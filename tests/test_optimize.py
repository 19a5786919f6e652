"""Bounded optimisation: the reparametrisation, convergence to known optima (inside the box and
on its boundary), the smoothed gradient estimator against the closed form for a quadratic, and
recovery of a pendulum's length from its motion (pathwise and smoothed gradients)."""

import json
import math
import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from jaxdeploy.batch import run_scene
from jaxdeploy.optimize import MACHINABLE, Box, Scatter, optimize
from jaxdeploy.scenes import DeployArray, Pendulum

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BOUNDS = {"panel1_ra": MACHINABLE["ra"], "panel1_clearance": MACHINABLE["clearance"]}


def test_box_round_trip_stays_inside_and_refuses_bad_input():
    box = Box({**BOUNDS, "restitution": (0.0, 1.0)})
    x = {"panel1_ra": 1.6e-6, "panel1_clearance": 5e-5, "restitution": 0.3}
    back = box.to_params(box.from_params(x))
    for k in x:
        assert float(back[k]) == pytest.approx(x[k], rel=1e-12)
    for u in (-60.0, 60.0):
        p = box.to_params(jnp.full(3, u))
        for k, (lo, hi) in box.bounds.items():
            assert lo <= float(p[k]) <= hi
    with pytest.raises(ValueError, match="panel1_ra"):
        box.from_params({**x, "panel1_ra": 7e-6})
    with pytest.raises(ValueError, match="low < high"):
        Box({"c": (2.0, 1.0)})


def _log_quadratic(target):
    """J = Σ (ln x − ln x*)² (a bowl in the log-coordinates the box uses)."""

    def loss(x):
        return sum((jnp.log(x[k]) - math.log(target[k])) ** 2 for k in target)

    return loss


def test_adam_finds_an_interior_optimum_and_stops_at_the_bound():
    inside = {"panel1_ra": 3.2e-6, "panel1_clearance": 2e-5}
    start = {"panel1_ra": 0.8e-6, "panel1_clearance": 1e-4}
    result = optimize(_log_quadratic(inside), start, BOUNDS, steps=150, learning_rate=0.2)
    for k in inside:
        assert result.optimum[k] == pytest.approx(inside[k], rel=1e-3)
    assert result.objective[result.best] < 1e-5 < result.objective[0]
    # The optimum outside the box (Ra 20 µm): the iterate stops at the upper bound 6.3 µm.
    outside = {"panel1_ra": 20e-6, "panel1_clearance": 2e-5}
    result = optimize(_log_quadratic(outside), start, BOUNDS, steps=150, learning_rate=0.3)
    assert result.optimum["panel1_ra"] == pytest.approx(6.3e-6, rel=1e-2)
    assert result.optimum["panel1_ra"] <= 6.3e-6


def test_the_best_iterate_is_returned_not_the_last():
    # A large Adam step overshoots the bowl's minimum: the iterates oscillate about it, so
    # the last is not the lowest; the result is the lowest, whatever its position.
    target = {"panel1_ra": 1.6e-6, "panel1_clearance": 5e-5}
    start = {"panel1_ra": 0.3e-6, "panel1_clearance": 1e-5}
    result = optimize(_log_quadratic(target), start, BOUNDS, steps=12, learning_rate=2.0)
    values = np.asarray(result.objective)
    assert result.status == "ok" and result.best == int(np.argmin(values))
    assert result.best != len(values) - 1, "the test needs an overshooting last step"
    assert result.optimum == result.x[result.best]
    record = result.to_json()
    assert record["optimum_objective"] == min(values) < record["last_objective"]


def test_a_nan_objective_stops_the_run_with_a_failed_status_and_keeps_the_best():
    # A batch loss (called once per iteration, in Python) whose "simulation" fails from the
    # fourth iteration on: NaN.
    calls = []
    bounds = {"panel1_ra": MACHINABLE["ra"]}

    def batch(designs):
        calls.append(None)
        x = np.asarray(designs["panel1_ra"])
        values = (np.log(x) - math.log(1.6e-6)) ** 2
        if len(calls) > 3:
            values = np.full_like(values, np.nan)
        return values, {}, np.isfinite(values)

    smoothing = Scatter(relative={"panel1_ra": 0.05}, pairs=2, seed=1)
    result = optimize(batch, {"panel1_ra": 0.5e-6}, bounds, steps=10, smoothing=smoothing)
    assert result.status.startswith("failed at iteration 3")
    assert len(result.x) == 4 and result.ok == [True, True, True, False]
    assert result.best is not None and result.best < 3
    record = result.to_json()
    assert record["status"] != "ok" and record["optimum"] == result.x[result.best]
    # Every iterate failing: no optimum, said so.
    calls.clear()
    calls.extend([None] * 10)
    failed = optimize(batch, {"panel1_ra": 0.5e-6}, bounds, steps=10, smoothing=smoothing)
    assert failed.status != "ok" and failed.best is None and failed.optimum is None


def test_smoothed_gradient_of_a_quadratic_matches_its_closed_form():
    """J(y) = a·y + ½ Σ b_k y_k², y = (ln x_1, x_2): E[J(y + sξ)] = J(y) + ½ Σ b_k s_k² and
    ∇E[J(y + sξ)] = a + b y exactly; the estimator's error is statistical (checked at 5 σ)."""
    a, b = np.array([0.7, -2.0e4]), np.array([3.0, 4.0e8])
    x = {"p": 2.0, "q": 3e-5}
    scatter = Scatter(relative={"p": 0.1}, absolute={"q": 1e-6}, pairs=20000, seed=1)
    draws = scatter.draws(np.random.default_rng(scatter.seed))
    designs = scatter.antithetic(x, draws)
    y = np.stack([np.log(designs["p"]), designs["q"]], axis=-1)
    values = y @ a + 0.5 * (y**2) @ b
    value, gradient = scatter.estimate(values, draws)
    y0 = np.array([math.log(2.0), 3e-5])
    s = np.array([0.1, 1e-6])
    exact = a + b * y0
    assert value == pytest.approx(y0 @ a + 0.5 * y0**2 @ b + 0.5 * (b * s**2).sum(), rel=1e-3)
    # Antithetic pairs cancel the even part; the odd part's estimate has sd |b_k y_k| ... /√M.
    for k, name in enumerate(("p", "q")):
        sd = np.sqrt(np.sum(exact**2 * (s / s[k]) ** 2) / scatter.pairs)
        assert abs(gradient[name] - exact[k]) < 5 * sd
    with pytest.raises(ValueError, match="must be > 0"):
        Scatter(relative={"p": 0.0})


def _pendulum_fit():
    """Loss: mean squared difference of the angle from a reference run of length 1.3 m."""
    scene = Pendulum()
    base = scene.resolve_params({"initial_angle": -0.4})
    reference = run_scene(scene, {**base, "length": 1.3}, 0.6, n_save=31).q[:, 2]

    def loss(x):
        q = run_scene(scene, {**base, **x}, 0.6, n_save=31).q[:, 2]
        return jnp.mean((q - reference) ** 2)

    return loss


def test_pendulum_length_recovered_by_pathwise_and_smoothed_gradients():
    loss = _pendulum_fit()
    bounds = {"length": (0.5, 3.0)}
    schedule = optax.exponential_decay(0.1, transition_steps=10, decay_rate=0.6)
    pathwise = optimize(loss, {"length": 2.2}, bounds, steps=40, optimizer=optax.adam(schedule))
    assert pathwise.optimum["length"] == pytest.approx(1.3, rel=2e-3)
    # dJ/dx reported by optimize equals central differences of the loss.
    x = pathwise.x[3]["length"]
    compiled = jax.jit(loss)  # the length is data: one program for both sides
    fd = (float(compiled({"length": x + 1e-6})) - float(compiled({"length": x - 1e-6}))) / 2e-6
    assert pathwise.gradient[3]["length"] == pytest.approx(fd, rel=1e-5)

    batch = jax.jit(jax.vmap(loss))

    def batch_loss(designs):
        values = np.asarray(batch({k: jnp.asarray(v) for k, v in designs.items()}))
        return values, {}, np.isfinite(values)

    smoothing = Scatter(relative={"length": 0.02}, pairs=4, seed=3)
    smoothed = optimize(
        batch_loss,
        {"length": 2.2},
        bounds,
        steps=50,
        optimizer=optax.adam(optax.exponential_decay(0.1, transition_steps=15, decay_rate=0.6)),
        smoothing=smoothing,
    )
    # Smoothing by 2 % in ln L shifts the minimiser by O(s²) only; the rest is SGD noise
    # (4 pairs per step, learning rate 0.1 → ~0.02 in u at the end).
    assert smoothed.optimum["length"] == pytest.approx(1.3, rel=5e-2)


def test_optimize_command_refuses_bad_input_before_running(tmp_path, capsys):
    from jaxdeploy.cli import main

    out = str(tmp_path / "o")
    cases = [
        (["--param", "panel1_roughness"], "unknown parameter 'panel1_roughness'"),
        (["--param", "restitution"], "no default bounds"),
        (["--param", "restitution=0.9:0.1"], "low < high"),
        (["--objective", "panel1:loudness=1"], "unknown"),
        (["--start", "restitution=0.5"], "not a design parameter"),
        (["--start", "panel1_ra=1e-5"], "--start panel1_ra = 1e-05 is invalid"),
        (["--start", "panel1_ra=1e-6", "--start", "panel1_ra=2e-6"], "given twice"),
        (["--learning-rate", "-1"], "--learning-rate = -1 is invalid"),
        (["--steps", "0"], "--steps = 0 is invalid"),
        (["--param", "panel1_ra", "--param", "panel1_ra"], "--param panel1_ra is given twice"),
        (["--param", "panel1_ra", "--set", "panel1_ra=1e-6"], "both a design parameter"),
        (["--scene-option", "friction_roughness"], "--scene-option expects KEY=VALUE"),
        (["--scene-option", "friction_roughness=x"], "--scene-option: friction_roughness = 'x'"),
        (["--scene", "pendulum", "--scene-option", "latch=x"], "--scene-option: "),
        (["--scene", "nope"], "unknown scene 'nope'"),
        # The option reaches the scene: with ploughing friction μ is no longer a parameter.
        (["--scene-option", "friction_roughness=ploughing", "--set", "friction_coefficient=0.1"],
         "counts with --scene-option friction_roughness=constant"),
        (["--set", "friction_adhesion=0.02"], "--scene-option friction_roughness=ploughing"),
        (["--derivative-change", "1e-3"], "--derivative-change is for --gradient pathwise"),
        (["--gradient", "pathwise", "--derivative-change", "1e-3", "--no-step-tolerance-check"],
         "exclude each other"),
        (["--gradient", "pathwise", "--derivative-change", "2"], "--derivative-change = 2"),
    ]  # fmt: skip
    for extra, message in cases:
        assert main(["optimize", "--out", out, *extra]) == 2
        assert message in capsys.readouterr().err
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "result.json").write_text("{}")
    assert main(["optimize", "--out", str(tmp_path / "full")]) == 2
    assert "--overwrite" in capsys.readouterr().err


@pytest.mark.slow
def test_optimize_command_end_to_end_on_a_short_deployment(tmp_path, capsys):
    """Two smoothed steps on panel 2's Ra over a 0.65 s deployment, with ploughing friction
    (`--scene-option`, recorded): writes the optimum, the history and the plot; the design
    stays inside the machinable box; one progress line per iteration with its count, elapsed
    time and (after the first, which compiles) an ETA."""
    import json

    from jaxdeploy.cli import main

    out = tmp_path / "opt"
    code = main(
        [
            "optimize",
            "--objective",
            "panel2:peak_vibration=1",
            "--param",
            "panel2_ra",
            "--t-end",
            "0.65",
            "--n-save",
            "1301",
            "--steps",
            "2",
            "--pairs",
            "1",
            "--scene-option",
            "friction_roughness=ploughing",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    progress = [line for line in capsys.readouterr().err.splitlines() if line.startswith("[")]
    assert [line.split("]")[0] for line in progress] == ["[1/2", "[2/2"]
    assert all("elapsed" in line for line in progress)
    assert "ETA" not in progress[0] and "ETA" in progress[1]
    record = json.loads((out / "result.json").read_text())
    assert len(record["history"]) == 2 and (out / "history.png").exists()
    assert 0.2e-6 <= record["optimum"]["panel2_ra"] <= 6.3e-6
    assert record["seed"] == 0 and "jax" in record["versions"]
    assert record["scene_options"]["friction_roughness"] == "ploughing"
    # Called in-process (not the command's own process), the devices are this process's.
    assert record["scatter"]["devices"] == jax.device_count()


# Batch and single runs decide their adaptive steps in differently compiled programs (a
# vmapped loop with masked lanes, and a plain one), so a decision can flip on round-off and
# they agree to the objective's integration error, not to round-off. The objective is the
# design's located events (lock time and panel 2's first contact onset, found inside their
# steps): well conditioned, unlike a post-lock peak vibration, which a relative change of
# panel2_ra by 1e-15 moved by 1e-3 relative (measured at 938a945), and which on an AVX-512
# build separated the two designs below by only half what an AVX2 build had (the test's
# earlier form failed there). Measured (default control, rtol 1e-6): the objective moves by
# 9.8e-8 and 4.7e-8 from rtol to rtol/10 (its integration error) for the two designs; batch
# minus single runs 1.3e-8 and 4.7e-9. The bound is twice the larger integration error; the
# designs' objectives differ by 0.38, 2e6 times it, so a case given another's parameters fails.
BATCH_SINGLE_ATOL = 2e-7


@pytest.mark.slow
def test_design_problem_batch_equals_single_runs():
    """evaluate_batch (one vmapped run) equals separate evaluations of the same designs, to
    the objective's integration error (BATCH_SINGLE_ATOL)."""
    from jaxdeploy.objectives import parse_objective
    from jaxdeploy.optimize import DesignProblem, evaluate_batch

    problem = DesignProblem(
        DeployArray(),
        parse_objective(["panel1:lock_time=1", "panel2:first_onset_time=1"]),
        0.65,
        n_save=1301,
    )
    cases = {"panel2_ra": [0.8e-6, 3.2e-6]}
    batch = evaluate_batch(problem, cases)
    assert list(batch["ok"]) == [True, True]
    assert abs(batch["objective"][1] - batch["objective"][0]) > 1e5 * BATCH_SINGLE_ATOL
    for i, ra in enumerate(cases["panel2_ra"]):
        value, parts, ok = problem.evaluate({"panel2_ra": ra})
        assert bool(ok)
        assert batch["objective"][i] == pytest.approx(float(value), rel=0, abs=BATCH_SINGLE_ATOL)
        # J = Σ ln(part): an absolute error of J is a relative error of its parts.
        for label, part in parts.items():
            assert batch["parts"][label][i] == pytest.approx(float(part), rel=BATCH_SINGLE_ATOL)


def test_forward_mode_optimizes_a_loss_whose_runs_only_forward_mode_can_differentiate():
    """`mode="forward"`: a loss whose runs use `diffrax.ForwardMode()` (reverse mode raises
    "Reverse-mode differentiation does not work for lax.while_loop" on it, the crash of
    `jaxdeploy optimize --gradient pathwise` before) gets the same gradient as reverse mode
    of the same loss with diffrax's default adjoint."""
    import diffrax as dfx

    scene = Pendulum()
    base = scene.resolve_params({"initial_angle": -0.4})

    def loss_with(adjoint):
        options = {} if adjoint is None else {"adjoint": adjoint}

        def loss(x):
            q = run_scene(scene, {**base, **x}, 0.3, n_save=16, **options).q[:, 2]
            return jnp.mean(q**2)

        return loss

    bounds = {"length": (0.5, 3.0)}
    forward = optimize(
        loss_with(dfx.ForwardMode()), {"length": 2.2}, bounds, steps=2, mode="forward"
    )
    reverse = optimize(loss_with(None), {"length": 2.2}, bounds, steps=2)
    assert forward.status == "ok"
    for a, b in zip(forward.gradient, reverse.gradient, strict=True):
        assert a["length"] == pytest.approx(b["length"], rel=1e-9)
    with pytest.raises(ValueError, match="mode = 'sideways' is invalid"):
        optimize(loss_with(None), {"length": 2.2}, bounds, steps=1, mode="sideways")


def test_pathwise_optimize_runs_at_the_tolerance_where_its_gradient_has_converged():
    """`optimize(..., control=, derivative_change=)`: the gradient at the start is evaluated at
    rtol, rtol/10, ... until it changes by at most the fraction (`fit.converged_tolerance`),
    the optimisation runs at that tolerance, and every tolerance runs one compiled program.
    Pendulum (no impacts) with adaptive Tsit5 steps from rtol 1e-2: a tolerance whose
    gradient has not converged is refused even where the loss is smooth."""
    import diffrax as dfx

    from jaxdeploy.solvers import StepControl

    scene = Pendulum()
    base = scene.resolve_params({"initial_angle": -0.4})
    tight = StepControl("tsit5", rtol=1e-10, atol=1e-13)
    reference = run_scene(scene, {**base, "length": 1.3}, 0.6, n_save=31, control=tight).q[:, 2]

    def loss(x, control):
        q = run_scene(
            scene, {**base, **x}, 0.6, n_save=31, control=control, adjoint=dfx.ForwardMode()
        ).q[:, 2]
        return jnp.mean((q - reference) ** 2)

    said = []
    result = optimize(
        loss, {"length": 2.2}, {"length": (0.5, 3.0)}, steps=2, mode="forward",
        control=StepControl("tsit5", rtol=1e-2, atol=1e-5), derivative_change=1e-5,
        progress=said.append,
    )  # fmt: skip
    found = result.step_tolerance
    assert result.status == "ok" and found.met is True
    # Each check compared the gradient at rtol with that at rtol/10; the search stopped at
    # the first within 1e-5, after at least one that was not (measured: 3.2e-5 from rtol 1e-2
    # to 1e-3; the pendulum's gradient converges fast, hence the small fraction).
    changes = [check["change"] for check in found.checks]
    assert changes[-1] <= 1e-5 and all(c > 1e-5 for c in changes[:-1]) and len(changes) >= 2
    assert found.rtol == pytest.approx(1e-2 * 10.0 ** -(len(changes) - 1))
    assert any("derivatives changed by" in line for line in said)
    # The optimisation's first gradient is the chosen tolerance's (dJ/du, reported in x).
    # found.derivatives are dJ/du; result.gradient dJ/dx = (dJ/du)/(dx/du), and for the log
    # map dx/du = x ln(hi/lo) s(1 − s), so at the chosen tolerance the two agree to round-off
    # (at rtol 1e-2 they would differ by more than the search's 1e-5).
    assert result.gradient[0]["length"] != 0
    ratio = found.derivatives["length"] / result.gradient[0]["length"]
    lo, hi = 0.5, 3.0
    s = (math.log(2.2) - math.log(lo)) / (math.log(hi) - math.log(lo))
    assert ratio == pytest.approx(2.2 * math.log(hi / lo) * s * (1 - s), rel=1e-9)
    assert result.to_json()["step_tolerance"]["rtol"] == found.rtol


@pytest.mark.slow  # ~2 min CPU: the ideal reference, one forward-mode deploy_array program to 0.6 s
def test_pathwise_optimize_runs_on_an_event_objective(tmp_path):
    """`jaxdeploy optimize --gradient pathwise` on the lock time (an event output, located
    and differentiated by the implicit-function theorem): it crashed before (ForwardMode under
    reverse mode); its gradient d ln t_L / d k must have the physics' sign (a stiffer spring
    locks sooner)."""
    import json

    from jaxdeploy.cli import main

    out = tmp_path / "opt"
    code = main([
        "optimize", "--scene", "deploy_array", "--objective", "panel1:lock_time=1",
        "--param", "spring_stiffness=1:3", "--gradient", "pathwise", "--steps", "2",
        "--t-end", "0.6", "--n-save", "61", "--quiet", "--out", str(out),
    ])  # fmt: skip
    assert code == 0
    record = json.loads((out / "result.json").read_text())
    assert record["gradient"] == "pathwise" and record["status"] == "ok"
    # The design ran at the tolerance where the start's gradient had converged (1e-3).
    found = record["step_tolerance"]
    assert found["met"] is True and found["checks"][-1]["change"] <= 1e-3
    assert record["step_control"]["rtol"] == found["rtol"]
    first = record["history"][0]
    assert 0.5 < first["parts"]["panel1:lock_time"] < 0.6
    assert first["gradient"]["spring_stiffness"] < 0


_SHARDED_BATCH = """
import json
import jax, jax.numpy as jnp, numpy as np
from jaxdeploy.optimize import BatchObjective

class Problem:  # J and its parts as DesignProblem.evaluate gives them, for one design
    def evaluate(self, x):
        a, b = x["a"], x["b"]
        return a * a + jnp.sin(b), {"a": a * a, "b": jnp.sin(b)}, a > 0

batch = BatchObjective(Problem())
designs = {"a": np.array([1.0, -2.0, 3.0]), "b": np.array([0.1, 0.2, 0.3])}
values, parts, ok = batch(designs)
text = batch._run.lower({k: jnp.asarray(np.r_[v, v[-1]]) for k, v in designs.items()}).as_text()
print(len(batch.devices), "shard_map" in text or "sdy.manual_computation" in text)
print(json.dumps([values.tolist(), parts["a"].tolist(), parts["b"].tolist(), ok.tolist()]))
"""


@pytest.mark.parametrize("devices", [1, 2])
def test_a_batch_of_designs_is_split_over_the_devices(devices):
    """`BatchObjective` runs its designs over every JAX device, each device a vmap of its
    share (`jax.shard_map`), padding a batch that does not divide evenly (3 designs on 2
    devices) and dropping the padding's results: the values are each design's own. In a
    new process with the CPU split into `devices` devices (JAX takes the count at start)."""
    env = dict(os.environ, XLA_FLAGS=f"--xla_force_host_platform_device_count={devices}")
    env["PYTHONPATH"] = ROOT + os.pathsep + env.get("PYTHONPATH", "")
    done = subprocess.run([sys.executable, "-c", _SHARDED_BATCH], env=env,
                          capture_output=True, text=True, timeout=300)  # fmt: skip
    assert done.returncode == 0, done.stderr
    first, second = done.stdout.strip().split("\n")
    assert first == f"{devices} {devices > 1}"
    a, b = np.array([1.0, -2.0, 3.0]), np.array([0.1, 0.2, 0.3])
    values, parts_a, parts_b, ok = json.loads(second)
    np.testing.assert_allclose(values, a * a + np.sin(b), rtol=1e-15)
    np.testing.assert_allclose(parts_a, a * a, rtol=1e-15)
    np.testing.assert_allclose(parts_b, np.sin(b), rtol=1e-15)
    assert ok == [True, False, True]


def test_a_design_batchs_programs_are_keyed_by_descriptions():
    """`BatchObjective`'s two programs (`_design_program`: the designs' runs, then their
    objective) are keyed by descriptions: equal problems built apart share them (one trace
    per process, and the program cache keeps them), another fixed value makes other runs, an
    objective weight another objective but the same runs (the runs return what the
    objective reads), an objective reading other outputs other runs, and a scene class
    defined outside jaxdeploy has none (compared by identity: traced per process)."""
    from jaxdeploy import _design_program
    from jaxdeploy.objectives import parse_objective
    from jaxdeploy.optimize import DesignProblem

    def specs(scene=None, objective="panel2:peak_vibration=1", **fixed):
        problem = DesignProblem(
            scene or DeployArray(), parse_objective(objective), 0.7, fixed=fixed,
            ideal_scene=None, n_save=701,
        )  # fmt: skip
        runs = _design_program.runs_spec(problem.runs, problem.objective, jax.devices())
        return runs, _design_program.objective_spec(problem)

    assert specs() == specs() and hash(specs()) == hash(specs())
    runs, objective = specs()
    assert "DesignRuns(" in repr(runs) and " at 0x" not in repr(runs)
    assert "DesignObjective(" in repr(objective) and " at 0x" not in repr(objective)
    assert specs(panel1_ra=1e-6)[0] != runs and specs(panel1_ra=1e-6) == specs(panel1_ra=1e-6)
    assert specs(panel1_ra=1e-6)[1] == objective  # the objective reads no parameter
    weighted = specs(objective="panel2:peak_vibration=2")
    assert weighted[0] == runs and weighted[1] != objective
    assert specs(objective="panel1:peak_vibration=1")[0] != runs  # panel 1's channels

    class OwnScene(DeployArray):
        pass

    own, _ = specs(OwnScene())
    assert own.static.description is None and own != specs(OwnScene())[0] and own == own
    assert " at 0x" in repr(own)


def test_the_design_runs_return_what_the_objective_reads():
    """`_design_program.objective_reads`: the channels and event outputs an objective reads
    (the batch's runs return only these: XLA leaves out what nobody reads), found by
    evaluating it on placeholders; None when that fails (then every output is returned, and
    the objective's own trace reports the problem)."""
    from jaxdeploy._design_program import objective_reads
    from jaxdeploy.objectives import parse_objective

    ts = np.linspace(0.0, 0.7, 701)
    channels, events = objective_reads(parse_objective("paper_reproducible"), ts)
    assert channels == {
        "panel1_tip_x", "panel1_tip_y", "panel2_tip_x", "panel2_tip_y", "panel2_tip_ax",
        "panel2_tip_ay",
    }  # fmt: skip
    assert events == set()
    channels, events = objective_reads(
        parse_objective(["panel1:lock_time=1", "panel2:max_contact_force=1"]), ts
    )
    assert channels == set() and events == {"lock_time", "panel2_peak_force"}
    channels, _ = objective_reads(parse_objective("panel1:dominant_frequency=-1"), ts)
    assert channels == {"panel1_tip_vx", "panel1_tip_vy"}  # interval means of the velocity
    # Too short for two windows: the evaluation fails, every output is kept.
    assert objective_reads(parse_objective("panel2:peak_vibration=1"), ts[:11]) is None

    # An objective of the user's own may read the outputs any way: all are kept.
    def total(deployment):
        return sum(jnp.sum(v) for v in deployment.channels.values())

    assert objective_reads(total, ts) is None

    class Whole(type(parse_objective("panel2:peak_vibration=1"))):
        pass

    assert objective_reads(Whole(parse_objective("panel2:peak_vibration=1").terms), ts) is None
    # The placeholders refuse to be looked at whole (a feature iterating them gives None).
    from jaxdeploy._design_program import _Reading, _ReadsWhole

    for look in (list, len, lambda m: m.items(), lambda m: m.values(), lambda m: {**m}):
        with pytest.raises(_ReadsWhole):
            look(_Reading(()))
