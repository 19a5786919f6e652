"""Reference solutions for the work–precision benchmark, with the evidence that they converged.

A reference is the index-1 ODE path (`MechanismODESolver`: same M, Φ, Q, contact laws and
memory as every other run) integrated by diffrax's 8th-order Dormand–Prince method at a tight
tolerance. Two things make that tolerance mean what it says on an impacting trajectory, and
both are what `simulate` does for every adaptive run: a step in which a clearance joint's v⁻ is
set (contact onset, or a peak of the approach speed) is redone to end just past that event
(`jaxdeploy.solvers.LocateEvents`; the memory's error is not seen by any error estimate), and
outputs between steps come from Dopri8's own 7th-order interpolant (`MechanismInterpolation`).
Before either, the reference needed steps landing on every output time and a largest step of
0.25 µs, and still agreed with the event-exact model only to ~3e-9 of c over the window; now
plain Dopri8 at 1e-12 agrees to ~1e-10 (docs/performance.md).

The evidence is Dopri8 itself at ten times looser tolerance, a second integrator (Tsit5, 5th
order, different error estimator, interpolant and step sequence) at ten times looser
tolerance, and, for slider_crank, an independent model: the numpy right-hand side with exact
contact events (`peers.py`) under scipy's DOP853 at rtol 1e-13. The differences, over the
reference window and over the whole horizon, bound the reference's own error (Hairer, Nørsett
& Wanner, *Solving ODEs I*, §II.10: the error of a tight run is estimated by comparing with a
looser one).

Errors are measured in each clearance joint's eccentricity `e = r_Pj − r_Pi` relative to its
clearance c: `max_t |e(t) − e_ref(t)| / c`, over the reference window (the first impacts,
where the reference is converged far below the benchmarked errors) and, separately, over the
full horizon (impacts amplify small differences, so errors grow there).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from jaxdeploy.io import atomic_write_json, atomic_write_npz
from jaxdeploy.mechanism import RevoluteClearance
from jaxdeploy.scenes import get_scene
from jaxdeploy.simulation import simulate

# End of the reference window [s]: slider_crank's first six impacts (the first onset is at
# 0.23 ms); deploy_array's first half second.
WINDOW = {"slider_crank": 1.5e-3, "deploy_array": 0.5}


def eccentricities(mechanism, q) -> np.ndarray:
    """`(N, J, 2)` eccentricity vectors of the J clearance joints over N states, each divided
    by its clearance c."""
    joints = [mechanism.elements[i] for i in mechanism.find(RevoluteClearance)]
    if not joints:
        raise ValueError("the mechanism has no clearance joint: no eccentricity to compare")

    def one(qk):
        kin = mechanism.kinematics(qk)
        return jnp.stack([j.geometry(kin).eccentricity / j.clearance for j in joints])

    return np.asarray(jax.jit(jax.vmap(one))(jnp.asarray(q)))


def eccentricity_error(mechanism, q, q_ref, ts, window_end) -> tuple[float, float]:
    """`(window, full)`: `max |e − e_ref| / c` over `t ≤ window_end` and over all `ts`."""
    diff = np.linalg.norm(eccentricities(mechanism, q) - eccentricities(mechanism, q_ref), axis=-1)
    diff = np.max(diff, axis=-1)
    diff = np.where(np.isfinite(diff), diff, np.inf)
    inside = np.asarray(ts) <= window_end
    return float(np.max(diff[inside])), float(np.max(diff))


@dataclass
class Reference:
    """A converged reference: states `q`, `v` at `ts`, the window, and the evidence."""

    scene: str
    params: dict
    ts: np.ndarray
    q: np.ndarray
    v: np.ndarray
    window_end: float
    rtol: float
    evidence: list = field(default_factory=list)

    @property
    def error_bound(self) -> tuple[float, float]:
        """(window, full): the smallest difference to a check run. Each difference bounds the
        sum of the two runs' errors (barring cancellation between independent runs), so the
        smallest one bounds the reference's own error; larger ones are mostly the looser
        checks' errors."""
        return (
            min(e["window"] for e in self.evidence),
            min(e["full"] for e in self.evidence),
        )

    def save(self, folder: str) -> None:
        """Write `reference.npz` (ts, q, v) and `reference.json` (the rest) into `folder`,
        atomically: a benchmark worker, or a resumed benchmark, reads them back (`load`)."""
        atomic_write_npz(os.path.join(folder, "reference.npz"), ts=self.ts, q=self.q, v=self.v)
        atomic_write_json(
            os.path.join(folder, "reference.json"),
            dict(
                scene=self.scene,
                params=self.params,
                window_end=self.window_end,
                rtol=self.rtol,
                evidence=self.evidence,
            ),
        )

    @classmethod
    def load(cls, folder: str) -> Reference:
        """The reference `save` wrote into `folder`."""
        with open(os.path.join(folder, "reference.json"), encoding="utf-8") as f:
            meta = json.load(f)
        with np.load(os.path.join(folder, "reference.npz")) as arrays:
            ts, q, v = (np.array(arrays[k]) for k in ("ts", "q", "v"))
        return cls(
            scene=meta["scene"],
            params=meta["params"],
            ts=ts,
            q=q,
            v=v,
            window_end=meta["window_end"],
            rtol=meta["rtol"],
            evidence=meta["evidence"],
        )

    @classmethod
    def exists_in(cls, folder: str) -> bool:
        return all(
            os.path.exists(os.path.join(folder, f"reference.{ext}")) for ext in ("npz", "json")
        )


def reference_solution(
    scene_name: str = "slider_crank",
    *,
    t_end: float | None = None,
    n_save: int = 1201,
    rtol: float = 1e-12,
    window_end: float | None = None,
    params: dict | None = None,
    max_steps: int = 5_000_000,
) -> Reference:
    """Compute the reference of `scene_name` (default parameters updated with `params`) on
    `n_save` equally spaced times up to `t_end` (default: the scene's), with Dopri8 at `rtol`
    (`atol = rtol/100` in m, m/s, rad), and its convergence evidence (module docstring).

    **Returns:** a `Reference`; `evidence` lists, for each check run, its method, tolerance and
    the differences `window`/`full` to the reference.
    """
    scene = get_scene(scene_name)
    p = scene.resolve_params(params)
    mech = scene.build(p)
    s0 = scene.initial_state(p, mech)
    t_end = scene.default_t_end if t_end is None else t_end
    window_end = min(WINDOW.get(scene_name, t_end), t_end) if window_end is None else window_end
    ts = np.linspace(0.0, t_end, n_save)

    def run(solver, tol):
        tr = simulate(
            mech, s0, t_end, ts=ts, solver=solver, rtol=tol, atol=tol * 1e-2, max_steps=max_steps
        )
        if not tr.ok:
            raise RuntimeError(f"reference run {solver} rtol={tol:g}: {tr.status()}")
        return tr

    ref = run("dopri8", rtol)
    ref_q = np.asarray(ref.q)
    evidence = []
    for solver in ("dopri8", "tsit5"):
        tol = 10 * rtol
        check = run(solver, tol)
        window, full = eccentricity_error(mech, np.asarray(check.q), ref_q, ts, window_end)
        steps = int(check.stats["num_accepted_steps"])
        evidence.append(dict(solver=solver, rtol=tol, window=window, full=full, steps=steps))
    if scene_name == "slider_crank":
        from .peers import SliderCrankNumpy

        tol = 1e-13
        peer = SliderCrankNumpy(p, scene.impact_velocity_rule).solve(
            s0, t_end, ts, "DOP853", tol, tol * 1e-2
        )
        if not peer.ok:
            raise RuntimeError(f"reference check, numpy model: {peer.message}")
        window, full = eccentricity_error(mech, peer.ys[:, : ref_q.shape[1]], ref_q, ts, window_end)
        evidence.append(
            dict(
                solver="numpy model + scipy DOP853, exact contact events",
                rtol=tol,
                window=window,
                full=full,
                steps=peer.n_steps,
            )
        )
    return Reference(scene_name, p, ts, ref_q, np.asarray(ref.v), window_end, rtol, evidence)
