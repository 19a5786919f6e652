"""Robustness (issue 8): nothing is lost when a write dies, results say what produced them,
extreme cases finish or say why not, and gradients stay finite at the special points."""

import json
import os
import shutil
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from jaxdeploy import io
from jaxdeploy.cli import main

# --- nothing lost ------------------------------------------------------------------------------


def _leftovers(folder):
    return [name for name in os.listdir(folder) if name.startswith(io.TEMP_PREFIX)]


def test_failed_write_keeps_the_previous_file_and_leaves_no_temporary(tmp_path, monkeypatch):
    target = tmp_path / "summary.json"
    io.atomic_write_json(str(target), {"run": 1})

    real_fsync = os.fsync

    def dying_fsync(fd):
        raise OSError("disk full (simulated)")

    monkeypatch.setattr(os, "fsync", dying_fsync)
    with pytest.raises(OSError, match="simulated"):
        io.atomic_write_json(str(target), {"run": 2, "big": list(range(10_000))})
    monkeypatch.setattr(os, "fsync", real_fsync)
    assert json.loads(target.read_text()) == {"run": 1}
    assert _leftovers(tmp_path) == []


def test_a_result_gets_the_permissions_a_plain_write_would_give(tmp_path):
    # The temporary file is created private (0600); the renamed result must not stay so.
    import stat

    plain = tmp_path / "plain.txt"
    plain.write_text("x")
    target = tmp_path / "summary.json"
    io.atomic_write_json(str(target), {"run": 1})
    assert stat.S_IMODE(target.stat().st_mode) == stat.S_IMODE(plain.stat().st_mode)


def test_exception_inside_the_npz_writer_leaves_no_file(tmp_path, monkeypatch):
    target = tmp_path / "trajectory.npz"

    def broken(buffer, **arrays):
        buffer.write(b"PK\x03\x04 half an archive")
        raise KeyboardInterrupt  # Ctrl-C half-way through serialising

    monkeypatch.setattr(np, "savez_compressed", broken)
    with pytest.raises(KeyboardInterrupt):
        io.atomic_write_npz(str(target), q=np.zeros((1000, 9)))
    assert not target.exists()
    assert _leftovers(tmp_path) == []


def test_sigkill_in_the_middle_of_a_write_never_leaves_a_truncated_result(tmp_path):
    """A real process death (SIGKILL) after half of the bytes went to disk."""
    target = tmp_path / "summary.json"
    target.write_text('{"run": 1}\n')
    script = textwrap.dedent(
        f"""
        import os, signal
        import jaxdeploy.io as io

        class Dying:
            def __init__(self, fh):
                self.fh = fh
            def __enter__(self):
                return self
            def __exit__(self, *exc):
                return self.fh.__exit__(*exc)
            def write(self, data):
                self.fh.write(data[: len(data) // 2])
                self.fh.flush()
                os.kill(os.getpid(), signal.SIGKILL)
            def __getattr__(self, name):
                return getattr(self.fh, name)

        real_fdopen = os.fdopen
        os.fdopen = lambda *a, **k: Dying(real_fdopen(*a, **k))
        io.atomic_write_json({str(target)!r}, {{"run": 2, "data": list(range(100000))}})
        """
    )
    proc = subprocess.run([sys.executable, "-c", script], env={**os.environ}, timeout=120)
    assert proc.returncode == -9  # it really died in the writer
    assert json.loads(target.read_text()) == {"run": 1}
    # The half-written bytes exist only in the hidden temporary file.
    leftovers = _leftovers(tmp_path)
    assert len(leftovers) == 1 and (tmp_path / leftovers[0]).stat().st_size > 0


def test_a_crashed_rerun_cannot_pass_for_a_complete_result(tmp_path, monkeypatch):
    """With --overwrite, a rerun that dies leaves the previous complete result as it was (the
    rerun writes into a staging folder that replaces it only when complete: issue 30), never
    a mix of old and new files."""
    out = tmp_path / "run"
    args = ["simulate", "pendulum", "--t-end", "0.05", "--out", str(out), "--quiet"]
    assert main(args) == 0
    summary = json.loads((out / "summary.json").read_text())
    # Parameters, versions and seed are recorded with the result.
    assert summary["params"] == {"length": 1.0, "mass": 1.0, "initial_angle": 0.0, "gravity": 9.81}
    assert {"jaxdeploy", "jax", "diffrax", "numpy", "python"} <= set(summary["versions"])
    assert "seed" in summary and summary["seed"] is None

    import jaxdeploy.io

    def dying_npz(path, **arrays):
        raise RuntimeError("killed while writing the trajectory (simulated)")

    monkeypatch.setattr(jaxdeploy.io, "atomic_write_npz", dying_npz)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    with pytest.raises(RuntimeError, match="simulated"):
        main([*args, "--overwrite"])
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert _leftovers(out) == [] and sorted(os.listdir(tmp_path)) == ["run"]


def _git(folder, *args):
    cmd = ["git", "-C", str(folder), "-c", "user.name=t", "-c", "user.email=t@t", *args]
    return subprocess.run(cmd, capture_output=True, text=True, check=True).stdout.strip()


@pytest.mark.skipif(shutil.which("git") is None, reason="git is not installed")
def test_results_record_the_git_commit_and_dirty_flag_of_a_checkout_and_none_otherwise(
    tmp_path, monkeypatch
):
    # A package tracked in a repository: its commit, clean, then dirty once a tracked file
    # changes (an untracked file, e.g. a result, does not count).
    repo, package = tmp_path / "repo", tmp_path / "repo" / "pkg"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("x = 1\n")
    _git(repo, "init", "-q")
    _git(repo, "add", "pkg/__init__.py")
    _git(repo, "commit", "-q", "-m", "first")
    commit = _git(repo, "log", "-1", "--format=%H")
    (package / "result.json").write_text("{}")
    assert io.code_revision(str(package)) == {"commit": commit, "dirty": False}
    # Nor does a generated page written beside the run (docs/, README.md: `io.GENERATED`):
    # the design study's runs were marked dirty by pages another generator was writing.
    (repo / "docs").mkdir()
    for page in ("docs/page.md", "README.md"):
        (repo / page).write_text("a\n")
        _git(repo, "add", page)
    _git(repo, "commit", "-q", "-m", "pages")
    commit = _git(repo, "log", "-1", "--format=%H")
    for page in ("docs/page.md", "README.md"):
        (repo / page).write_text("b\n")
    assert io.code_revision(str(package)) == {"commit": commit, "dirty": False}
    (package / "__init__.py").write_text("x = 2\n")
    assert io.code_revision(str(package)) == {"commit": commit, "dirty": True}
    # Not a checkout: a plain folder, and an untracked copy inside a repository (a wheel
    # installed into a .venv that lives in a checkout).
    plain = tmp_path / "site-packages" / "pkg"
    plain.mkdir(parents=True)
    (plain / "__init__.py").write_text("x = 1\n")
    assert io.code_revision(str(plain)) is None
    venv = repo / ".venv" / "pkg"
    venv.mkdir(parents=True)
    (venv / "__init__.py").write_text("x = 1\n")
    assert io.code_revision(str(venv)) is None
    # git missing or hanging: no revision, no error.
    monkeypatch.setenv("PATH", str(tmp_path / "nowhere"))
    assert io.code_revision(str(package)) is None
    monkeypatch.undo()

    def hanging(*args, **kwargs):
        raise subprocess.TimeoutExpired(args[0], io.GIT_TIMEOUT)

    monkeypatch.setattr(subprocess, "run", hanging)
    assert io.code_revision(str(package)) is None
    monkeypatch.undo()
    # Every result's metadata carries it (None if these tests run against an installed wheel).
    this = io.run_metadata()["git"]
    here = os.path.dirname(os.path.abspath(io.__file__))
    tracked = subprocess.run(["git", "-C", here, "ls-files", "--error-unmatch", "__init__.py"],
                             capture_output=True).returncode == 0  # fmt: skip
    if tracked:
        assert this is not None and this["commit"] == _git(here, "log", "-1", "--format=%H")
    else:
        assert this is None


def test_figures_are_written_atomically(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    io.atomic_savefig(fig, str(tmp_path / "f.png"), dpi=50)
    plt.close(fig)
    assert (tmp_path / "f.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert _leftovers(tmp_path) == []


# --- extreme impacts: complete, finite, energy balance, no stall, finite gradients ------------

import diffrax as dfx  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

from jaxdeploy import contact  # noqa: E402
from jaxdeploy.mechanism import (  # noqa: E402
    Body,
    CoilSpringDrive,
    Latch,
    Mechanism,
    Revolute,
    add_clock,
    consistent_state,
    energy_balance,
    energy_moved,
    metered,
)
from jaxdeploy.scenes import Impact  # noqa: E402
from jaxdeploy.simulation import simulate  # noqa: E402


def test_energy_moved_is_the_largest_energy_in_motion_plus_the_largest_injection():
    # T + D peaks at 3 + 1 = 4 (not at the end); |J| peaks at 0.5 (a negative injection).
    balance = {
        "kinetic": np.array([0.0, 3.0, 1.0]),
        "dissipated": np.array([0.0, 1.0, 2.0]),
        "injected": np.array([0.0, -0.5, 0.2]),
    }
    assert energy_moved(balance) == 4.5


# (clearance m, σ m, E Pa, c_e, v0 m/s): the corners of issue 8's matrix that one impact reaches.
EXTREME_IMPACTS = [
    (1e-6, 1e-6, 207e9, 0.9, 1.0),  # 1 µm clearance, σ as large as the clearance
    (1e-7, 1e-8, 400e9, 0.5, 0.1),  # 0.1 µm, stiffest material
    (1e-5, 1e-5, 1e9, 0.05, 10.0),  # softest, hardest impact, σ = c: in contact from t = 0
    (1e-6, 1e-9, 400e9, 1.0, 10.0),  # elastic impact, σ → 0 (Hertz)
]
ENERGY_TOLERANCE = 2e-3  # |T + V + D − E0| / E0 over the whole run (stated in docs/robustness.md)


def _impact_case(clearance, sigma, modulus, restitution, speed):
    scene = Impact(damping="flores")
    stiffness = contact.journal_bearing_stiffness(5e-3, clearance, modulus, 0.3, modulus, 0.3)
    params = scene.resolve_params(
        {
            "clearance": clearance,
            "sigma": sigma,
            "stiffness": float(stiffness),
            "restitution": restitution,
            "impact_speed": speed,
            "mass": 1.0,
        }
    )
    mechanism = metered(scene.build(params))
    return add_clock(mechanism, scene.initial_state(params, mechanism))


def test_extreme_impacts_complete_balance_energy_and_do_not_stall():
    cases = [_impact_case(*case) for case in EXTREME_IMPACTS]
    mechanism = jax.tree.map(lambda *xs: jnp.stack(xs), *[m for m, _ in cases])
    initial = jax.tree.map(lambda *xs: jnp.stack(xs), *[s for _, s in cases])

    def run(mech, init):
        traj = simulate(mech, init, 1e-3, rtol=1e-8, atol=1e-13, dt_max=1e-5, n_save=21)
        ok = traj.result == dfx.RESULTS.successful
        return ok, traj.q, traj.v, traj.memory, traj.stats["num_rejected_steps"]

    # One compiled program (outside `jit` the batched set-up around the solve runs op by op).
    ok, q, v, memory, rejected = jax.jit(jax.vmap(run))(mechanism, initial)
    for k, case in enumerate(EXTREME_IMPACTS):
        mech_k = cases[k][0]
        mem_k = jax.tree.map(lambda x, k=k: x[k], memory)
        assert bool(ok[k]), f"{case}: the solve failed"
        assert np.all(np.isfinite(np.asarray(q[k]))) and np.all(np.isfinite(np.asarray(v[k])))
        balance = energy_balance(mech_k, q[k], v[k], mem_k)
        e0 = 0.5 * case[4] ** 2
        assert float(np.max(np.abs(balance["residual"]))) <= ENERGY_TOLERANCE * e0, case
        dissipated = np.asarray(balance["dissipated"])
        assert dissipated[-1] >= -1e-9 * e0  # the damping law never creates energy
        # Rebound: the journal comes back (it left the centre at +v0 along x); the gap is
        # microns, so it then rattles in the bearing.
        assert float(np.min(np.asarray(v[k][:, 0]))) < 0.0
        if case[3] == 1.0:  # elastic (χ = 0): nothing dissipated, T + V stays at E0
            assert abs(dissipated[-1]) <= 1e-12 * e0
            stored = balance["kinetic"][-1] + balance["potential"][-1]
            assert float(stored) == pytest.approx(e0, rel=ENERGY_TOLERANCE)
        clock = mech_k.elements[-1]
        log = mem_k[len(mech_k.elements) - 1]
        assert type(clock).__name__ == "StepClock"
        # No stall: a bounded number of steps, and few rejections.
        assert float(log["steps"][-1]) < 2e5 and int(rejected[k]) < float(log["steps"][-1])
        # Every step at least 1e-5 of the contact's time scale — except where the journal
        # starts inside the rough law's range (σ ≥ c/3, onset at −3σ ≤ −c): that contact begins
        # at rest, so the classical rule's v⁻ is the law's impact_velocity_floor (1e-4 m/s) and
        # the damping χ F_e δ̇/v_floor sets a far shorter time scale (measured: 4.4e-13 s for
        # c = σ = 10 µm at 10 m/s, 2621 steps; 1.3e-9 s with the running_max rule).
        clearance, sigma = case[0], case[1]
        if 3.0 * sigma < clearance:
            assert float(log["min_step"][-1]) >= 1e-12


def _rebound_speed(params_vector):
    """Final x-velocity of the Flores impact as a function of (c, σ, c_e, v0); starts centred."""
    clearance, sigma, restitution, speed = params_vector
    scene = Impact(damping="flores")
    stiffness = contact.journal_bearing_stiffness(5e-3, clearance, 207e9, 0.3, 207e9, 0.3)
    params = dict(scene.default_params())
    params.update(clearance=clearance, sigma=sigma, stiffness=stiffness)
    params.update(restitution=restitution, impact_speed=speed)
    mechanism = scene.build(params)
    initial = scene.initial_state(params, mechanism)
    traj = simulate(mechanism, initial, 2e-4, rtol=1e-8, atol=1e-13, dt_max=1e-6, n_save=2)
    return traj.v[-1, 0]


def test_approach_speed_is_right_when_the_onset_step_also_crosses_the_centre():
    # A journal 0.139 µm from the centre flies through it at 0.894 m/s towards the far side:
    # the first step (10 µs) crosses the centre (δ̇ jumps from −v to +v there) and the rough
    # law's onset 7 µm beyond. v⁻ must be the flight speed, as it is with short steps.
    scene = Impact(damping="flores")
    k = float(contact.journal_bearing_stiffness(5e-3, 1e-5, 1e9, 0.3, 1e9, 0.3))
    params = scene.resolve_params(
        {"clearance": 1e-5, "sigma": 1e-6, "stiffness": k, "restitution": 0.9}
    )
    mech = scene.build(params)
    speed = 0.894
    init = consistent_state(
        mech, jnp.array([1.39e-7, 0.0, 0.0]), jnp.array([-speed, 0.0, 0.0]), fixed_velocities=(0,)
    )
    for first_step in (1e-7, 1e-5):
        traj = simulate(mech, init, 1.2e-5, n_save=2, dt=first_step, rtol=1e-8, atol=1e-13,
                        dt_max=1e-5)  # fmt: skip
        assert float(traj.memory[0]["in_contact"][-1]) == 1.0
        v_minus = float(traj.memory[0]["impact_velocity"][-1])
        assert v_minus == pytest.approx(speed, rel=1e-4), (first_step, v_minus)


@pytest.mark.slow  # 30 s of the default suite at 844cb65 (2 cores): kept out of it
def test_gradients_finite_from_zero_eccentricity_through_contact_onset_and_rebound():
    """The journal starts exactly centred (e = 0), crosses the rough law's onset, impacts and
    rebounds; the gradient with respect to every contact parameter is finite, and its signs are
    the physical ones: a higher restitution and a faster approach give a faster rebound."""
    x = jnp.array([1e-5, 1e-6, 0.7, 0.3])
    speed, grad = jax.jit(jax.value_and_grad(_rebound_speed))(x)  # one compiled program
    assert np.all(np.isfinite(np.asarray(grad))), grad
    assert float(speed) < 0.0
    assert float(grad[2]) < 0.0  # d(v_x)/d c_e: v_x = −(rebound speed), which grows with c_e
    assert float(grad[3]) < 0.0  # d(v_x)/d v0


def test_clearance_forces_have_finite_gradients_at_zero_eccentricity_and_sliding_speed():
    law = contact.LankaraniNikravesh(contact.RoughElastic(1e10, 1e-6), 0.9)
    friction = contact.SmoothCoulomb(0.8)

    def forces(q, v, clearance):
        from jaxdeploy.mechanism import RevoluteClearance

        joint = RevoluteClearance(
            "ground", "B", "journal", "c", clearance=clearance, journal_radius=5e-3,
            normal=law, friction=friction,
        )  # fmt: skip
        body = Body("journal", 1.0, 1e-5, {"c": (0.0, 0.0)})
        mech = Mechanism([body], [joint], {"B": (0.0, 0.0)})
        return mech.generalized_forces(q, v, 0.0, mech.init_memory(q, v))

    # Compiled: run op by op, the first use of each operation compiles it (14 s against 4 s).
    jacobians = jax.jit(jax.jacfwd(forces, argnums=(0, 1, 2)))
    gradients = jax.jit(jax.grad(lambda q, v, c: jnp.sum(forces(q, v, c)), argnums=(0, 1, 2)))
    zero = jnp.zeros(3)
    for q in (zero, jnp.array([1e-5, 0.0, 0.0])):  # centred; exactly at the nominal surface
        for jac in jacobians(q, zero, 1e-5):
            assert np.all(np.isfinite(np.asarray(jac)))
        for g in gradients(q, zero, 1e-5):
            assert np.all(np.isfinite(np.asarray(g)))


def test_gradient_finite_across_latch_engagement():
    """A panel driven by a coil spring swings to its latch, which engages mid-run."""

    def final_angle(stiffnesses):
        spring, latch = stiffnesses
        panel = Body("panel", 1.0, 0.1, {"hinge": (-0.5, 0.0)})
        mech = Mechanism(
            [panel],
            [
                Revolute("ground", "O", "panel", "hinge"),
                CoilSpringDrive("ground", "panel", stiffness=spring, free_angle=2.0),
                Latch("ground", "panel", lock_angle=1.0, stiffness=latch, damping=5.0),
            ],
            {"O": (0.0, 0.0)},
        )
        init = consistent_state(mech, jnp.array([0.5, 0.0, 0.0]), fixed=(2,))
        traj = simulate(mech, init, 1.5, dt=2e-3, n_save=2)
        return traj.q[-1, 2], traj.memory[2]["engaged"][-1]

    # One compiled program gives the run's values (for the differences too) and its gradient.
    angle_and_grad = jax.jit(jax.value_and_grad(final_angle, has_aux=True))
    x = jnp.array([1.0, 500.0])
    (angle, engaged), grad = angle_and_grad(x)
    assert float(engaged) == 1.0 and abs(float(angle) - 1.0) < 0.05
    assert np.all(np.isfinite(np.asarray(grad)))
    assert float(grad[1]) != 0.0  # the latch stiffness matters after engagement
    # Against central differences of the same fixed-step map (the engagement stays in the
    # same step for relative changes of 1e-6).
    for k in range(2):
        step = 1e-6 * float(x[k])
        dx = jnp.zeros(2).at[k].set(step)
        (plus, _), _ = angle_and_grad(x + dx)
        (minus, _), _ = angle_and_grad(x - dx)
        fd = (float(plus) - float(minus)) / (2 * step)
        assert float(grad[k]) == pytest.approx(fd, rel=1e-5, abs=1e-9), k


def _pressed_pair(*elements):
    """Two bodies a, b and a ground point S; b's hole sits 13 µm from a's pin, 3 µm past a
    10 µm clearance. **Returns:** the mechanism of `elements` and that q."""
    a = Body("a", 2.0, 0.1, {"p": (0.3, 0.1), "pin": (-0.2, 0.0)})
    b = Body("b", 1.0, 0.05, {"p": (-0.1, 0.2), "hole": (0.1, 0.0)})
    mech = Mechanism([a, b], list(elements), {"S": (1.0, 1.0)})
    q = jnp.array([0.1, 0.2, 0.3, 0.0, 0.0, 0.5])
    pin = mech.kinematics(q).position("a", "pin")
    hole_offset = mech.kinematics(q).position("b", "hole") - q[3:5]
    q = q.at[3:5].set(pin + jnp.array([13e-6, 0.0]) - hole_offset)
    return mech, q


def test_potential_energies_are_the_conservative_forces():
    """`Q(q, 0) = −∇V(q)` when nothing dissipates: gravity, springs, cubic drive, applied loads,
    an engaged latch and a penetrating rough contact, each against its own potential."""
    from jaxdeploy.mechanism import (
        AppliedForce,
        AppliedTorque,
        Gravity,
        RevoluteClearance,
        RotationalSpring,
        Spring,
    )

    elastic = contact.RoughElastic(1e9, 2e-6, offset=1.0)
    elements = [
        Gravity((0.3, -9.81)),
        Spring("ground", "S", "a", "p", stiffness=50.0, rest_length=0.4),
        RotationalSpring("a", "b", stiffness=3.0, rest_angle=0.2),
        CoilSpringDrive("ground", "a", stiffness=2.0, free_angle=1.5, cubic_stiffness=0.7),
        AppliedTorque("b", 0.4),
        AppliedForce("b", "p", (1.0, -2.0)),
        Latch("a", "b", lock_angle=0.1, stiffness=40.0),
        RevoluteClearance(
            "b",
            "hole",
            "a",
            "pin",
            clearance=1e-5,
            journal_radius=5e-3,
            normal=contact.Undamped(elastic),
        ),  # fmt: skip
    ]
    mech, q = _pressed_pair(*elements)
    memory = list(mech.init_memory(q, jnp.zeros(6)))
    memory[6] = {"engaged": jnp.asarray(1.0)}
    memory = tuple(memory)
    # Compiled (op by op each operation's first use compiles it).
    forces = jax.jit(lambda q, m: mech.generalized_forces(q, jnp.zeros(6), 0.0, m))(q, memory)
    grad_v = jax.jit(jax.grad(lambda q, m: mech.potential_energy(q, m)))(q, memory)
    np.testing.assert_allclose(np.asarray(forces), -np.asarray(grad_v), rtol=1e-10, atol=1e-9)
    assert float(elements[-1].potential_energy(mech.kinematics(q), None)) > 0.0


def test_elements_declared_conservative_dissipate_nothing():
    """An element class declaring `conservative` is skipped by the energy meter: its force
    must be `−∇V` at any state, moving too (every declaring class is checked here)."""
    from jaxdeploy import mechanism as mech_module
    from jaxdeploy.mechanism import AbstractElement, Gravity

    declared = {
        c.__name__
        for c in vars(mech_module).values()
        if isinstance(c, type) and issubclass(c, AbstractElement) and c.conservative
    }
    elements = [
        Gravity((0.3, -9.81)),
        CoilSpringDrive("a", "b", stiffness=2.0, free_angle=1.5, cubic_stiffness=0.7),
    ]
    assert declared == {type(e).__name__ for e in elements}
    mech, q = _pressed_pair(*elements)
    v = jnp.array([0.3, -0.2, 1.1, -0.4, 0.2, -2.0])
    memory = mech.init_memory(q, v)
    forces = jax.jit(lambda q, m: mech.generalized_forces(q, v, 0.0, m))(q, memory)
    grad_v = jax.jit(jax.grad(lambda q, m: mech.potential_energy(q, m)))(q, memory)
    np.testing.assert_allclose(np.asarray(forces), -np.asarray(grad_v), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("approach", [0.02, -0.02])  # δ̇ > 0 approaching, < 0 receding
def test_closed_form_nonconservative_contact_force_is_the_force_plus_the_potential_gradient(
    approach,
):
    """`RevoluteClearance.nonconservative_wrenches` (what the energy meter books as
    dissipated) against `Q + ∇_q V` computed generically, with damping, friction and rough
    surfaces, the journal moving into or out of the bore."""
    from jaxdeploy.mechanism import RevoluteClearance
    from jaxdeploy.mechanism.meters import EnergyMeter

    joint = RevoluteClearance(
        "b", "hole", "a", "pin", clearance=1e-5, journal_radius=5e-3,
        normal=contact.LankaraniNikravesh(contact.RoughElastic(1e9, 2e-6, offset=1.0), 0.7),
        friction=contact.SmoothCoulomb(0.2),
    )  # fmt: skip
    mech, q = _pressed_pair(joint)
    # b moves along the line of centres (+x: deeper) and slides across it (y).
    v = jnp.array([0.0, 0.0, 0.0, approach, 0.5, 0.0])
    (joint_memory,) = mech.init_memory(q, v)
    assert float(joint_memory["in_contact"]) == 1.0
    memory = ({**joint_memory, "impact_velocity": jnp.asarray(0.05)},)  # v⁻ of this contact
    kin = mech.kinematics(q, v)
    closed = jax.jit(lambda m: EnergyMeter(joint)._nonconservative_force(kin, m))(memory[0])
    generic = jax.jit(
        lambda m: (
            mech.generalized_forces(q, v, 0.0, (m,))
            + jax.grad(lambda x: mech.potential_energy(x, (m,)))(q)
        )
    )(memory[0])
    forces = mech.generalized_forces(q, v, 0.0, memory)
    scale = float(jnp.max(jnp.abs(forces)))
    assert scale > 1.0 and float(jnp.max(jnp.abs(generic))) > 0.1 * scale  # it dissipates
    np.testing.assert_allclose(np.asarray(closed), np.asarray(generic), rtol=0, atol=1e-12 * scale)


def test_energy_meter_does_not_change_the_dynamics():
    scene = Impact(damping="hunt_crossley")
    params = scene.resolve_params({"restitution": 0.6})
    plain = scene.build(params)
    wrapped = metered(plain)
    runs = [
        simulate(m, scene.initial_state(params, m), 6e-4, dt=2e-6, n_save=5)
        for m in (plain, wrapped)
    ]
    np.testing.assert_array_equal(np.asarray(runs[0].q), np.asarray(runs[1].q))
    balance = energy_balance(wrapped, runs[1].q, runs[1].v, runs[1].memory)
    # Hunt–Crossley with c_e = 0.6: the energy lost is (1 − c_eff²) E0, c_eff ≈ c_e.
    lost = float(balance["dissipated"][-1]) / 0.5
    rebound = -float(runs[1].v[-1, 0])
    assert lost == pytest.approx(1.0 - rebound**2, abs=2e-3)


def test_energy_meter_keeps_event_location():
    """A metered clearance joint still reports its v⁻ events, so an adaptive metered run
    locates them and steps exactly as the plain one (the meter used to hide them: metered
    runs then took other steps than the runs they instrument)."""
    scene = Impact(damping="flores")
    params = scene.resolve_params()
    plain = scene.build(params)
    wrapped = metered(plain)
    runs = [
        simulate(m, scene.initial_state(params, m), 6e-4, rtol=1e-8, atol=1e-13, n_save=5)
        for m in (plain, wrapped)
    ]
    assert all(run.ok for run in runs)
    for key in ("num_accepted_steps", "num_rejected_steps"):
        assert int(runs[0].stats[key]) == int(runs[1].stats[key]), key
    np.testing.assert_allclose(np.asarray(runs[0].q), np.asarray(runs[1].q), rtol=1e-12, atol=0)


def test_a_leftover_partial_write_is_not_a_result(tmp_path):
    """A killed writer leaves only its hidden temporary file: the folder holds no result, so
    it is not refused, and preparing it removes the leftover. A real file is still refused."""
    from jaxdeploy.io import TEMP_PREFIX, check_output_dir, prepare_output_dir

    out = tmp_path / "run"
    out.mkdir()
    leftover = out / f"{TEMP_PREFIX}abc-summary.json"
    leftover.write_text('{"half": ')
    check_output_dir(str(out), overwrite=False)
    prepare_output_dir(str(out), overwrite=False)
    assert not leftover.exists()
    (out / "summary.json").write_text("{}")
    with pytest.raises(FileExistsError, match="already holds results"):
        check_output_dir(str(out), overwrite=False)


def test_a_clocked_pendulum_under_gravity_balances_energy():
    """The step clock of `add_clock` is bookkeeping, not matter: gravity leaves it alone, so a
    frictionless pendulum's T + V stays at its initial value (before the fix the clock body fell
    and its lost potential showed as an energy residual of g²t²/2 per kg)."""
    from jaxdeploy.mechanism import Gravity

    rod = Body("rod", 1.0, 1.0 / 12.0, {"pin": (-0.5, 0.0)})
    mech = metered(Mechanism([rod], [Revolute("ground", "O", "rod", "pin"), Gravity()],
                             {"O": (0.0, 0.0)}))  # fmt: skip
    init = consistent_state(mech, jnp.array([0.5, 0.0, 0.0]))  # horizontal, at rest
    clocked, clocked_init = add_clock(mech, init)
    traj = simulate(clocked, clocked_init, 0.5, rtol=1e-10, atol=1e-12, n_save=11)
    assert traj.result == dfx.RESULTS.successful
    balance = energy_balance(clocked, traj.q, traj.v, traj.memory)
    kinetic = np.asarray(balance["kinetic"])
    assert kinetic[-1] > 1.0  # the rod has swung down (about 4.9 J at the bottom)
    assert float(np.max(np.abs(np.asarray(balance["residual"])))) < 1e-6 * kinetic.max()
    clock_x = np.asarray(traj.q[:, -3])
    np.testing.assert_allclose(clock_x, np.asarray(traj.ts), rtol=0, atol=1e-12)
