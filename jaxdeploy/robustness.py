"""Can a run be trusted? The checks of docs/robustness.md, for any scene and parameter set.

`check_run` runs a scene once and answers, in one JSON-ready record: did the solver finish,
are all states finite, does the energy balance close, do the outputs agree with the same run
at a tighter tolerance and with an independent formulation, and are forward-mode derivatives
of the outputs finite. `experiments/robustness.py` applies it to a matrix of extreme cases.

The energy balance is `T + V + D = T(0) + V(0) + J` (`jaxdeploy.mechanism.energy_balance`,
dissipation D metered inside the run, J the energy put in by memory updates such as a latch
engaging); its residual is judged against `energy_moved`, the most energy ever in motion,
dissipated or put in.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np

from .mechanism import add_clock, energy_balance, energy_moved, metered, step_log
from .scenes import Scene
from .simulation import Trajectory, simulate
from .solvers import StepControl

Outputs = Callable[[Trajectory], jax.Array]


def energy_summary(mechanism, traj: Trajectory) -> dict:
    """The energy balance of a run of a `metered` mechanism, as numbers [J]: `moved_J`
    (`energy_moved`), `residual_J` max_t |T + V + D − T(0) − V(0) − J|, `residual_rel` (their
    ratio), `dissipated_J` D and `injected_J` J at the end, and `dissipated_by_J` (element
    index → D of that element at the end)."""
    balance = energy_balance(mechanism, traj.q, traj.v, traj.memory)
    moved = energy_moved(balance)
    residual = float(np.max(np.abs(np.asarray(balance["residual"]))))
    return {
        "moved_J": moved,
        "residual_J": residual,
        "residual_rel": residual / moved,
        "dissipated_J": float(np.asarray(balance["dissipated"])[-1]),
        "injected_J": float(np.asarray(balance["injected"])[-1]),
        "dissipated_by_J": {
            int(i): float(np.asarray(d)[-1]) for i, d in balance["dissipated_by"].items()
        },
    }


def relative_difference(values, reference, scale) -> float:
    """max |values − reference| / scale, each output by its own scale (`scale` broadcasts
    against the outputs' leading axes, e.g. one scale per output of a time series)."""
    a, b = np.asarray(values), np.asarray(reference)
    scale = np.maximum(np.asarray(scale, dtype=float), 1e-300)
    scale = scale.reshape(scale.shape + (1,) * (b.ndim - scale.ndim))
    return float(np.max(np.abs(a - b) / scale))


def comparison_solver(control: StepControl) -> str:
    """The independent formulation a run is compared with: generalized-α on the index-3
    equations is checked against the index-1 ODE with projection (Kvaerno5, implicit like it,
    so stiff contacts cost both alike), any diffrax solver against generalized-α."""
    return "kvaerno5" if control.solver_name() == "generalized_alpha" else "generalized_alpha"


def directional_derivative(
    scene: Scene, params: dict, t_end: float, control: StepControl, outputs: Outputs, n_save: int
) -> dict:
    """Forward-mode derivative of `outputs` along p_k → p_k (1 + s) for every nonzero
    parameter at once (parameters exactly 0 stay Python floats: they select what is traced),
    of the run over its own accepted steps (`simulate(..., replay_steps=True)`).

    **Returns:** `gradient_finite` (no partial derivative is NaN or inf), `gradient_max_abs`
    (largest finite |d outputs / ds|), `gradient_wall_s`; for a time series of outputs that
    stops being finite, `gradient_nonfinite_from_s` (the first saved time where it is not)
    and `gradient_max_abs_before` (how large it had grown by then: a tangent that grows
    exponentially in chaotic motion overflows late, a singular formula gives NaN at once).
    """
    names = [k for k, v in params.items() if float(v) != 0.0]
    base = jnp.asarray([float(params[k]) for k in names])

    def f(s):
        p = dict(params)
        p.update({k: base[i] * (1.0 + s) for i, k in enumerate(names)})
        mech = scene.build(p)
        traj = simulate(
            mech, scene.initial_state(p, mech), t_end, control=control, n_save=n_save,
            adjoint=dfx.ForwardMode(), replay_steps=True,
        )  # fmt: skip
        return outputs(traj)

    start = time.perf_counter()
    _, tangent = jax.jvp(f, (jnp.zeros(()),), (jnp.ones(()),))
    tangent = np.asarray(tangent)
    finite = np.isfinite(tangent)
    record = {
        "gradient_finite": bool(np.all(finite)),
        "gradient_max_abs": float(np.max(np.abs(tangent[finite]), initial=0.0)),
        "gradient_wall_s": time.perf_counter() - start,
    }
    if not record["gradient_finite"] and tangent.shape[:1] == (n_save,):
        bad = int(np.argmax(~np.all(finite.reshape(n_save, -1), axis=1)))
        record["gradient_nonfinite_from_s"] = float(t_end * bad / (n_save - 1))
        record["gradient_max_abs_before"] = float(np.max(np.abs(tangent[:bad]), initial=0.0))
    return record


def _timed_run(mech, init, t_end, control, n_save):
    start = time.perf_counter()
    traj = simulate(mech, init, t_end, control=control, n_save=n_save)
    traj.q.block_until_ready()
    return traj, time.perf_counter() - start


def _finite(traj) -> bool:
    return bool(np.all(np.isfinite(np.asarray(traj.q))) and np.all(np.isfinite(traj.v)))


def check_run(
    scene: Scene,
    params: dict,
    t_end: float,
    control: StepControl,
    outputs: Outputs,
    scale: Outputs,
    *,
    n_save: int = 201,
    tighten: float = 10.0,
    compare_t_end: float = np.inf,
    derivative: bool = True,
) -> dict:
    """Run `scene` with `params` for `t_end` [s] under `control` and check the run.

    **Arguments:**
    - `outputs`: the quantities compared between runs, a function of a `Trajectory`;
      `scale`: the scale of each (a function of the reference `Trajectory`), so that a
      difference is relative.
    - `tighten`: the tighter run divides rtol and atol by it (same compiled program:
      tolerances are data).
    - `compare_t_end`: how much of the run [s] the comparison solver (`comparison_solver`)
      repeats; a shorter window is compared with the checked solver over the same window.
    - `derivative`: compute `directional_derivative`.

    **Returns:** a record: `solver`, `status`, `finite`, `steps`, `rejected`, `min_step`,
    `max_step` (from a clock body, `add_clock`), `wall_s`; `energy_residual_rel`,
    `energy_moved_J`, `dissipated_J`, `injected_J` (`energy_summary`); `ref_difference_rel`
    (outputs vs the tighter run), `ref_dissipated_difference_rel` (dissipated energy vs it,
    relative to the energy moved), `ref_energy_residual_rel`, `ref_wall_s`; `other_solver`
    (`solver`, `status`, `t_end`, `steps`, `wall_s`, `difference_rel`,
    `dissipated_difference_rel`); and the `directional_derivative` fields.
    """
    record = {"params": {k: float(v) for k, v in params.items()}, "t_end": t_end}
    record["solver"] = control.solver_name()
    mech = metered(scene.build(params))
    init = scene.initial_state(params, mech)
    clocked, clocked_init = add_clock(mech, init)
    traj, record["wall_s"] = _timed_run(clocked, clocked_init, t_end, control, n_save)
    record["status"] = traj.status()
    record["finite"] = _finite(traj)
    record["steps"] = int(traj.stats["num_accepted_steps"])
    record["rejected"] = int(traj.stats["num_rejected_steps"])
    record.update(step_log(clocked, traj.memory))
    energy = energy_summary(clocked, traj) if record["finite"] else None
    if energy:
        record["energy_moved_J"] = energy["moved_J"]
        record["energy_residual_rel"] = energy["residual_rel"]
        record["dissipated_J"] = energy["dissipated_J"]
        record["injected_J"] = energy["injected_J"]

    tight = control.replace(
        rtol=control.rtol / tighten, atol=None if control.atol is None else control.atol / tighten
    )
    ref, record["ref_wall_s"] = _timed_run(clocked, clocked_init, t_end, tight, n_save)
    record["ref_status"] = ref.status()
    record["ref_difference_rel"] = relative_difference(outputs(traj), outputs(ref), scale(ref))
    if energy and _finite(ref):
        ref_energy = energy_summary(clocked, ref)
        d_ref = abs(energy["dissipated_J"] - ref_energy["dissipated_J"])
        record["ref_dissipated_difference_rel"] = d_ref / energy["moved_J"]
        record["ref_energy_residual_rel"] = ref_energy["residual_J"] / energy["moved_J"]

    window = min(t_end, compare_t_end)
    if window < t_end:
        short, _ = _timed_run(mech, init, window, control, n_save)
        short_energy = energy_summary(mech, short) if short.ok and _finite(short) else None
    else:
        short, short_energy = traj, energy
    other = control.replace(solver=comparison_solver(control))
    run, wall = _timed_run(mech, init, window, other, n_save)
    compared = {
        "solver": other.solver_name(),
        "status": run.status(),
        "t_end": window,
        "steps": int(run.stats["num_accepted_steps"]),
        "wall_s": wall,
        "difference_rel": relative_difference(outputs(run), outputs(short), scale(short)),
    }
    if run.ok and short_energy:
        d = abs(energy_summary(mech, run)["dissipated_J"] - short_energy["dissipated_J"])
        compared["dissipated_difference_rel"] = d / short_energy["moved_J"]
    record["other_solver"] = compared
    if derivative:
        record.update(directional_derivative(scene, params, t_end, control, outputs, n_save))
    return record
