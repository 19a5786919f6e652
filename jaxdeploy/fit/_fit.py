"""Fitting scene parameters to measurements: Levenberg–Marquardt on noise-weighted residuals,
with uncertainties from the Gauss–Newton curvature at the optimum.

The model is `run_scene` (the whole simulation is a JAX function of the parameters); the
Jacobian of the residuals with respect to the internal (bounded, `FitParameter`) coordinates
comes from forward-mode AD through the solver (`jax.jacfwd` with `diffrax.ForwardMode`: one
tangent per fitted parameter, so the cost grows with the number of parameters, which is small
here). Residuals and Jacobian are one compiled function, evaluated once per LM trial step.

The optimiser (`levenberg_marquardt`) is Levenberg–Marquardt with Marquardt's diagonal
scaling and Nielsen's damping update (Madsen, Nielsen & Tingleff 2004, Alg. 3.16), a loop in
Python around the compiled evaluation, so that every trial is reported (progress, loss
history) and a failed simulation is a rejected step, not a NaN inside the optimiser. Its
comparison with optimistix's `LevenbergMarquardt` on our problems:
`experiments/identification_solvers.py` (docs/identification.md).

Rugged losses (impacts make the loss jump between basins: a guess 50 % off in restitution
can sit in another basin) get a global first stage, `starts=N`: N points of a Latin hypercube
over the bounded box (McKay, Beckman & Conover, *Technometrics* 21 (1979) 239), uniform in
the internal coordinate's logistic variable s (so in ln θ for positive parameters), plus the
guess, are simulated as one vmapped batch, and LM starts from the one with the lowest cost.

Uncertainty (e.g. Bates & Watts, *Nonlinear Regression Analysis*, 1988, §2.3): with residuals
in noise units, the covariance of the estimates is `C = (J_θᵀ J_θ)⁻¹`, J_θ the Jacobian in
physical units at the optimum; when the noise level was not given it is estimated,
`C = s² (J_θᵀ J_θ)⁻¹`, `s² = χ²/(N − p)`. Standard errors `√C_ii`, correlations
`C_ij/√(C_ii C_jj)`. A parameter the channels do not determine shows as a standard error
comparable to or larger than the value, or a correlation near ±1 with another parameter;
the singular values of the relative Jacobian `J_θ diag(θ)` say how well each direction of
parameter space is seen.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from . import _model_program
from ._adequacy import assess
from ._data import Measurements
from ._parameters import FitParameter, internal_vector, make_parameters
from ._residuals import Comparison, ResidualSpec
from ._schedule import tighten, tighter

# A parameter whose standard error exceeds this fraction of its value is reported as not
# identified; a pair with |correlation| above CORRELATED as confounded.
NOT_IDENTIFIED = 0.5
CORRELATED = 0.95
# LM keeps the internal coordinates in [−ZMAX, ZMAX] (further, dθ/dz underflows and the
# parameter's column of the Jacobian is lost to roundoff). A parameter with |z| ≥ AT_BOUND,
# within e^(−15) ≈ 3e-7 of a bound in the logistic variable, is reported "at its bound": an
# optimiser crawling towards a bound it cannot cross slows down long before ZMAX.
ZMAX = 20.0
AT_BOUND = 15.0
# `tolerance_check`: the fit is reported not reproducible when a 10x tighter model tolerance
# changes the model by more than this many noise levels RMS, or would move an estimate by
# more than this many standard errors.
REPRODUCIBLE = 1.0
# `refit_until_reproducible`: the tightest rtol a tolerance check runs at (so the tightest
# refit is at 10x this). Below ~1e-12 a float64 run's error estimate approaches round-off.
RTOL_CHECK_FLOOR = 1e-12
# `tolerance_check`: the Jacobian ∂r/∂θ at the estimate counts as converged when no parameter's
# column changes by more than this fraction (relative, 2-norm) at a 10x tighter tolerance (the
# rule of `derivative_tolerance`). Why 1e-2 for a fit: a relative error ε of the Jacobian
# changes each standard error by ≲ ε and moves the Gauss–Newton optimum, whose condition is
# Jᵀr = 0, by δθ = (JᵀJ)⁻¹ΔJᵀr ≈ ε standard errors for white residuals in noise units; 1 %
# keeps both below the standard error's own sampling uncertainty, 1/√(2(N − p)) = 1 % at
# N = 5000 residuals.
JACOBIAN_CHANGE = 1e-2


@dataclass
class FitResult:
    """What a fit found and how well determined it is (see the module docstring)."""

    parameters: list[FitParameter]
    estimates: dict[str, float]
    standard_errors: dict[str, float]
    correlation: np.ndarray
    covariance: np.ndarray
    singular_values: np.ndarray
    chi2: float
    n_residuals: int
    noise_known: bool
    iterations: int
    evaluations: int
    converged: bool
    message: str
    history: list[dict]
    wall_time: float
    comparison: Comparison
    model_initial: dict[str, np.ndarray]
    model_final: dict[str, np.ndarray]
    stages: list[dict] = field(default_factory=list)
    # The first stage's comparison: `model_initial` holds the channels at its save times.
    comparison_initial: Comparison | None = None
    # Parameters whose bounded map saturated (dθ/dz = 0: the fit drove them onto a bound),
    # and the directions of parameter space (unit vectors in ln θ, `{name: component}`) the
    # curvature does not see at all (singular values at roundoff level).
    at_bound: list[str] = field(default_factory=list)
    unresolved: list[dict[str, float]] = field(default_factory=list)
    # The verdict of `_adequacy.assess` on the last stage's residuals.
    adequacy: dict = field(default_factory=dict)
    # ∂r/∂θ at the optimum (physical units; zero columns for parameters at a bound).
    jacobian: np.ndarray | None = None
    # `tolerance_check`'s record (None until it ran).
    tolerance: dict | None = None
    # The compiled model and the internal point of the estimate (what `tolerance_check`
    # evaluates the Jacobian at a tighter tolerance with); not part of the report.
    model: object = field(default=None, repr=False)
    z: np.ndarray | None = field(default=None, repr=False)
    # The step control the last stage ran at (`fit(model_error=...)` may have tightened the
    # one it was given between stages); what `tolerance_check` must start from.
    control: object = field(default=None, repr=False)

    @property
    def derivatives_converged(self) -> bool | None:
        """Whether ∂r/∂θ at the estimate changes by at most `JACOBIAN_CHANGE` (relative, per
        parameter) at a 10x tighter tolerance (`tolerance_check`); None when not checked."""
        return (self.tolerance or {}).get("derivatives_converged")

    @property
    def adequate(self) -> bool:
        """Whether the model explains the data: χ²/dof consistent with the stated noise and
        white residuals (`_adequacy`). Independent of `converged`."""
        return bool(self.adequacy.get("adequate", False))

    @property
    def reproducible(self) -> bool | None:
        """Whether the model at the estimate is reproducible at the noise level (`tolerance_check`:
        a 10x tighter tolerance changes it by at most `REPRODUCIBLE` noise levels RMS and
        would move no estimate by more than `REPRODUCIBLE` standard errors); None when the
        check did not run or could not (fixed step, tighter run failed)."""
        return (self.tolerance or {}).get("reproducible")

    @property
    def inflation(self) -> float:
        """√(χ²/dof) when the noise level was given and χ²/dof > 1, else 1: the factor that
        turns the curvature's standard errors into ones consistent with the residuals' actual
        scatter (Bates & Watts 1988, §2.3, with s² = χ²/dof in place of the stated σ²)."""
        rc = self.reduced_chi2
        return math.sqrt(rc) if self.noise_known and math.isfinite(rc) and rc > 1 else 1.0

    @property
    def standard_errors_inflated(self) -> dict[str, float]:
        return {n: self.inflation * se for n, se in self.standard_errors.items()}

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.parameters]

    @property
    def reduced_chi2(self) -> float:
        dof = self.n_residuals - len(self.parameters)
        return self.chi2 / dof if dof > 0 else math.nan

    def relative_errors(self) -> dict[str, float]:
        return {n: self.standard_errors[n] / abs(self.estimates[n]) for n in self.names}

    def not_identified(self) -> list[str]:
        return [n for n, r in self.relative_errors().items() if not r <= NOT_IDENTIFIED]

    def confounded_pairs(self) -> list[tuple[str, str, float]]:
        """Pairs with a finite correlation beyond ±`CORRELATED`. A correlation is NaN when
        one of the two has an infinite standard error (at a bound, or along a direction the
        data do not see): such pairs are not counted here; `unresolved_combinations` says
        which parameters share an unseen direction."""
        out = []
        for i, a in enumerate(self.names):
            for j in range(i + 1, len(self.names)):
                c = float(self.correlation[i, j])
                if math.isfinite(c) and abs(c) > CORRELATED:
                    out.append((a, self.names[j], c))
        return out

    def unresolved_combinations(self, threshold: float = 0.01) -> list[dict[str, float]]:
        """The unseen directions that mix two or more parameters not at a bound (components
        of the unit vector in ln θ above `threshold`): the data fix every combination of
        these parameters except this one (e.g. E and ν, seen only through E/(1 − ν²))."""
        out = []
        for direction in self.unresolved:
            kept = {n: c for n, c in direction.items() if abs(c) > threshold}
            if len(kept) >= 2:
                out.append(kept)
        return out

    def flags(self) -> list[str]:
        """One sentence per problem the residuals or the curvature show (empty: the model
        explains the data, every parameter is determined and no pair is confounded)."""
        out = [
            "MODEL DOES NOT EXPLAIN THE DATA: " + reason
            for reason in self.adequacy.get("reasons", [])
        ]
        if self.reproducible is False:
            tol = self.tolerance
            out.append(
                "MODEL NOT REPRODUCIBLE AT THE NOISE LEVEL: at rtol "
                f"{tol['rtol_check']:g} instead of {tol['rtol']:g} the model at the estimate moves "
                f"{tol['rms_model_change_over_sigma']:.3g} noise levels RMS and a refit would move "
                f"an estimate by up to {tol['largest_estimate_change_in_standard_errors']:.3g} "
                f"standard errors (limit {REPRODUCIBLE:g}): the fit matched the integration "
                "error; give a tighter --rtol or fit a shorter record"
            )
        if self.derivatives_converged is False:
            tol = self.tolerance
            out.append(
                "DERIVATIVES NOT CONVERGED: at rtol "
                f"{tol['rtol_check']:g} instead of {tol['rtol']:g} the Jacobian at the estimate "
                f"changes by {tol['jacobian_change']:.3g} (limit {JACOBIAN_CHANGE:g}), the "
                f"standard errors by up to {tol['standard_error_change']:.3g}: give a tighter "
                "--rtol"
            )
        out += [f"{n} is at its bound (the data push it beyond)" for n in self.at_bound]
        out += [
            f"{n} is not identified (std. error > {NOT_IDENTIFIED:.0%} of the value)"
            for n in self.not_identified()
            if n not in self.at_bound
        ]
        out += [
            f"{a} and {b} are confounded (correlation {c:+.3f})"
            for a, b, c in self.confounded_pairs()
        ]
        out += [
            "only a combination is unresolved: "
            + " ".join(f"{c:+.3f}·ln {n}" for n, c in combo.items())
            + " is not seen by the data"
            for combo in self.unresolved_combinations()
        ]
        return out

    def report(self) -> dict:
        """A JSON-ready summary."""
        return {
            "converged": self.converged,
            "adequate": self.adequate,
            "reproducible": self.reproducible,
            "derivatives_converged": self.derivatives_converged,
            "estimates": self.estimates,
            "standard_errors": self.standard_errors,
            "standard_errors_inflated": self.standard_errors_inflated,
            "inflation_factor": self.inflation,
            "relative_standard_errors": self.relative_errors(),
            "correlation": {
                a: {b: float(self.correlation[i, j]) for j, b in enumerate(self.names)}
                for i, a in enumerate(self.names)
            },
            "bounds": {p.name: [p.low, p.high] for p in self.parameters},
            "initial_guess": {p.name: p.guess for p in self.parameters},
            "singular_values_relative_jacobian": list(map(float, self.singular_values)),
            "not_identified": self.not_identified(),
            "confounded_pairs": [list(x) for x in self.confounded_pairs()],
            "at_bound": self.at_bound,
            "unresolved_directions": self.unresolved,
            "unresolved_combinations": self.unresolved_combinations(),
            "flags": self.flags(),
            "chi2": self.chi2,
            "n_residuals": self.n_residuals,
            "reduced_chi2": self.reduced_chi2,
            "noise": "given" if self.noise_known else "estimated from the residuals",
            "adequacy": self.adequacy,
            "tolerance": self.tolerance,
            "iterations": self.iterations,
            "evaluations": self.evaluations,
            "message": self.message,
            "wall_time_s": self.wall_time,
            "stages": self.stages,
        }


class Model:
    """The compiled map z → (model channels at the save times, their Jacobian d/dz, solver
    status) for one scene, one parameter set to fit and save times up to `ts`.

    Residuals are linear maps of the channel samples (samples, block means, kernel averages:
    `Comparison`), so their Jacobian is the same map applied to the channels' Jacobian. One
    compiled model therefore serves every residual stage (continuation in the smoothing
    width, and in the horizon: save times and the end time are data, so a stage that needs
    only the first n of `ts` runs to `ts[n − 1]` with the rest of the save times set to it;
    one compilation for the whole schedule).
    """

    def __init__(self, scene, parameters, fixed, names, ts, control, simulate_options):
        from ..batch import step_control
        from ._derivatives import _adaptive

        self.control = step_control(scene, control)
        if _adaptive(self.control):
            # Adaptive steps: differentiate the run over its own accepted steps (see
            # `simulate(..., replay_steps=True)`), not a loop that re-decides them.
            simulate_options = {"replay_steps": True, **simulate_options}
        self.ts = np.asarray(ts, dtype=float)
        # The model's programs are module-level functions of a description of everything
        # their trace depends on (`_model_program`), so the program cache keeps them between
        # processes. The step control's tolerances are data of the programs: the tolerance
        # check's Jacobian at a 10x tighter rtol (`tolerance_check`, with the method kept:
        # `_schedule.tighter`) compiles nothing more.
        self._parts = (scene, list(parameters), dict(fixed), list(names), dict(simulate_options))
        self._specs = {}  # by structure: one spec object each (compared by identity if need be)

    def _program(self, control):
        """`(ModelSpec, rtol, atol)` of the model's programs at `control`."""
        structure, rtol, atol = _model_program.tolerances(control)
        if structure not in self._specs:
            scene, parameters, fixed, names, options = self._parts
            self._specs[structure] = _model_program.spec(
                scene, parameters, fixed, names, structure, options
            )
        return self._specs[structure], rtol, atol

    def make_ready(self, z, control=None, on_traced=None) -> bool:
        """Trace (or read back) and compile the Jacobian's program at `control` (default the
        model's; only its structure matters, `_model_program.tolerances`) without running
        it, so that the first `self(z, ...)` at any tolerance of that structure, in any
        thread, runs it at once or waits for it (`_program_cache.ahead_of_time`): a caller
        may do this in a second thread while it chooses the tolerance (`jaxdeploy fit`).
        `on_traced()` is called once the program is traced and lowered (XLA's compile, which
        leaves Python's GIL free, follows). **Returns:** whether it was made (False: the
        program cache is off or the model cannot be kept; the first call traces it then)."""
        from .. import _program_cache

        try:
            with _program_cache.ahead_of_time(), _program_cache.when_traced(on_traced):
                self(z, control=control)
        except _program_cache.ProgramReady as ready:
            return ready.ready
        return False  # not reached: `ahead_of_time` raises before anything runs

    def save_times(self, n: int | None = None) -> np.ndarray:
        """The first `n` save times, padded with the last of them to the compiled length."""
        n = self.ts.size if n is None else int(n)
        if not 1 <= n <= self.ts.size:
            raise ValueError(f"n = {n} save times: must be in [1, {self.ts.size}]")
        return np.concatenate([self.ts[:n], np.full(self.ts.size - n, self.ts[n - 1])])

    def channels_batch(self, zs, n: int | None = None, control=None):
        """Channels of many points `zs` (k, p) as one vmapped batch: `({name: (k, N)}, ok)`
        (only the first `n` samples are the save times; see `save_times`). `control`: as in
        `__call__`."""
        zs, ts = np.asarray(zs, dtype=float), self.save_times(n)
        spec, rtol, atol = self._program(self.control if control is None else control)
        model, ok = _model_program.call(_model_program.channels_batch, spec, rtol, atol, zs, ts)
        return {n: np.asarray(v) for n, v in model.items()}, np.asarray(ok)

    def __call__(self, z, n: int | None = None, control=None):
        """`(channels, d channels/dz, ok)` at `z` up to the `n`-th save time: `{name: (N,)}`,
        `{name: (N, p)}`, of which the first `n` samples are the save times. `control`: a
        `StepControl` differing from the model's in its tolerances (default the model's)."""
        control = self.control if control is None else control
        spec, rtol, atol = self._program(control)
        z, ts = np.asarray(z, dtype=float), self.save_times(n)
        jac, (model, ok) = _model_program.call(_model_program.jacobian, spec, rtol, atol, z, ts)
        model = {n: np.asarray(v) for n, v in model.items()}
        jac = {n: np.asarray(v) for n, v in jac.items()}
        ok = bool(ok) and all(np.all(np.isfinite(v)) for v in (*model.values(), *jac.values()))
        return model, jac, ok


class StageModel:
    """`z → (r, J, channels, ok)` for LM: a compiled `Model`, one `Comparison` and the step
    control of the stage (default the model's; its tolerances are data of the program)."""

    def __init__(self, model: Model, comparison: Comparison, control=None):
        self.model, self.comparison = model, comparison
        self.control = model.control if control is None else control

    def costs(self, zs):
        """Costs ½|r|² of many points `zs` (k, p) as one vmapped batch; inf where the
        simulation failed or gave non-finite residuals."""
        channels, ok = self.model.channels_batch(zs, self.comparison.n_save, self.control)
        with np.errstate(invalid="ignore", over="ignore"):  # failed runs: NaN channels
            cost = self._costs(channels, ok)
        return np.where(ok & np.isfinite(cost), cost, np.inf)

    def _costs(self, channels, ok):
        return np.array(
            [
                0.5 * float(np.sum(r * r))
                for r in (
                    self.comparison.residuals_np({n: v[i] for n, v in channels.items()})
                    for i in range(len(ok))
                )
            ]
        )

    def __call__(self, z, control=None):
        n = self.comparison.n_save
        channels, jac, ok = self.model(z, n, self.control if control is None else control)
        channels = {name: v[:n] for name, v in channels.items()}
        r = self.comparison.residuals_np(channels)
        jr = self.comparison.residual_jacobian(jac)
        ok = ok and bool(np.all(np.isfinite(r))) and bool(np.all(np.isfinite(jr)))
        return r, jr, channels, ok


def latin_hypercube_starts(parameters, n: int, seed: int) -> np.ndarray:
    """`n` internal points `z` (n, p) of a Latin hypercube over the parameters' bounds: one
    point per stratum of s = logistic(z) in every coordinate, strata paired at random
    (McKay et al. 1979), kept 0.5/n away from the bounds."""
    rng = np.random.default_rng(seed)
    p = len(parameters)
    strata = np.stack([rng.permutation(n) for _ in range(p)], axis=1)
    s = (strata + rng.uniform(0.25, 0.75, size=(n, p))) / n
    return np.log(s / (1.0 - s))


def levenberg_marquardt(
    model: Callable,
    z0: np.ndarray,
    *,
    max_iterations: int = 30,
    ftol: float = 1e-8,
    ctol: float = 0.0,
    xtol: float = 1e-8,
    gtol: float = 1e-10,
    tau: float = 1e-3,
    zmax: float = math.inf,
    callback: Callable | None = None,
):
    """Minimise F(z) = ½|r(z)|² with `model(z) -> (r, J, aux, ok)`: Levenberg–Marquardt with
    Marquardt's diagonal scaling and Nielsen's damping update.

    The trial step h solves the damped Gauss–Newton problem

        (JᵀJ + μ D) h = −Jᵀr,   D = diag(JᵀJ)

    (Marquardt, *J. SIAM* 11 (1963) 431; the scaling makes the step invariant to the units of
    each coordinate, Moré, *Lecture Notes in Mathematics* 630 (1978) 105), solved as the
    least-squares problem [J; √μ D^½] h ≈ −[r; 0] (orthogonal factorisation, not the normal
    equations). The gain ratio ρ = (F(z) − F(z + h)) / (L(0) − L(h)), L(h) = ½|r + J h|² the
    Gauss–Newton model, accepts the step when ρ > 0 and updates μ ← μ·max(⅓, 1 − (2ρ − 1)³),
    ν ← 2; a rejection sets μ ← μν, ν ← 2ν (Madsen, Nielsen & Tingleff, *Methods for
    non-linear least squares problems*, 2nd ed., DTU 2004, Alg. 3.16 and eq. 3.14); μ starts
    at `tau`. A failed simulation (`ok` false) is a rejected step. Internal coordinates are
    kept in [−`zmax`, `zmax`].

    Stops before a trial whose step is below `xtol (|z| + xtol)` or whose predicted decrease
    L(0) − L(h) is below `ctol` (near the optimum an adaptive-step model's cost is noisy: a
    trial that could not lower F by a statistically relevant amount even if the model were
    linear is not worth a run), when |Jᵀr|_∞ ≤ `gtol`, when an accepted step lowers F by less
    than `ftol` relative or `ctol` absolute (residuals in noise units: F changes by ½ over one
    standard error), or after `max_iterations` trials. **Returns:** `(z, r, J, aux, info)` at
    the best accepted point, with the model's Jacobian there.
    """
    z = np.clip(np.asarray(z0, dtype=float), -zmax, zmax)
    r, jac, aux, ok = model(z)
    if not ok:
        raise RuntimeError(
            "the model cannot be evaluated at the initial guess (the simulation failed or "
            "gave non-finite outputs); change the guess, the bounds or the step control"
        )
    aux0 = aux
    cost = 0.5 * float(r @ r)
    history = [dict(iteration=0, cost=cost, accepted=True, step=0.0, z=z.tolist())]
    if callback:
        callback(history[-1])
    mu, nu = tau, 2.0
    evaluations, converged, message = 1, False, "maximum number of iterations reached"
    iteration = 0
    for iteration in range(1, max_iterations + 1):
        g = jac.T @ r
        if np.max(np.abs(g)) <= gtol:
            iteration -= 1
            converged, message = True, "gradient below tolerance"
            break
        d = np.sum(jac * jac, axis=0)
        d = np.maximum(d, 1e-12 * max(float(np.max(d)), 1e-300))
        augmented = np.vstack([jac, np.diag(np.sqrt(mu * d))])
        h = np.linalg.lstsq(augmented, -np.concatenate([r, np.zeros(z.size)]), rcond=None)[0]
        h = np.clip(z + h, -zmax, zmax) - z
        predicted = cost - 0.5 * float(np.sum((r + jac @ h) ** 2))  # L(0) − L(h)
        if np.linalg.norm(h) <= xtol * (np.linalg.norm(z) + xtol):
            iteration -= 1
            converged, message = True, "step below tolerance"
            break
        if predicted < ctol:
            iteration -= 1
            converged, message = True, "predicted decrease below ctol (statistically negligible)"
            break
        r_new, jac_new, aux_new, ok = model(z + h)
        evaluations += 1
        cost_new = 0.5 * float(r_new @ r_new) if ok else math.inf
        rho = (cost - cost_new) / predicted if predicted > 0 else -1.0
        accepted = ok and rho > 0
        history.append(
            dict(
                iteration=iteration,
                cost=cost_new,
                accepted=accepted,
                step=float(np.linalg.norm(h)),
                z=(z + h).tolist(),
                simulation_ok=ok,
            )
        )
        if callback:
            callback(history[-1])
        if not accepted:
            mu, nu = mu * nu, 2.0 * nu
            continue
        decrease = cost - cost_new
        z, r, jac, aux, cost = z + h, r_new, jac_new, aux_new, cost_new
        mu, nu = mu * max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), 2.0
        if decrease < ftol * (cost + decrease):
            converged, message = True, "relative cost decrease below tolerance"
            break
        if decrease < ctol:
            converged, message = True, "cost decrease below ctol (statistically negligible)"
            break
    info = dict(
        iterations=iteration,
        evaluations=evaluations,
        converged=converged,
        message=message,
        history=history,
        aux_initial=aux0,
    )
    return z, r, jac, aux, info


def _curvature(parameters, z, r, jac, noise_known):
    """Covariance, standard errors, correlations and singular values at the optimum."""
    theta = np.array([float(p.to_physical(zk)) for p, zk in zip(parameters, z, strict=True)])
    dtheta = np.array([p.dphysical_dz(zk) for p, zk in zip(parameters, z, strict=True)])
    # A parameter driven onto its bound has dθ/dz = 0 (the logistic map saturates): the data
    # say nothing about it there beyond "at the bound", so its column is left out (zero),
    # which gives it an infinite standard error below.
    at_bound = ~(np.abs(dtheta) > 0) | ~np.isfinite(dtheta)
    # Within e^(−AT_BOUND) of the bound in the logistic variable: "at the bound" for the
    # report; its column (still finite) is kept.
    pinned = np.abs(np.asarray(z)) >= AT_BOUND
    with np.errstate(invalid="ignore", divide="ignore"):
        jac_theta = np.where(at_bound, 0.0, jac / np.where(at_bound, 1.0, dtheta))  # ∂r/∂θ
    jac_rel = jac_theta * theta  # ∂r/∂ln θ: columns comparable across units
    _, s, vt = np.linalg.svd(jac_rel, full_matrices=False)
    # Moore–Penrose inverse of the curvature: directions it does not see (singular values at
    # roundoff level) are left out, and every parameter with a component along them gets an
    # infinite standard error; the others keep their finite marginal errors.
    seen = s > (s.max() if s.size else 0.0) * 1e-12
    cov_rel = (vt[seen].T / s[seen] ** 2) @ vt[seen]
    unseen = np.max(np.abs(vt[~seen]), axis=0) > 1e-6 if (~seen).any() else np.zeros(len(z), bool)
    cov_rel[unseen, :] = np.inf
    cov_rel[:, unseen] = np.inf
    chi2 = float(r @ r)
    n, p = r.size, len(parameters)
    if not noise_known and n > p:
        cov_rel = cov_rel * chi2 / (n - p)
    cov = cov_rel * np.outer(theta, theta)
    se = np.sqrt(np.diag(cov))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(se, se)
    corr = np.where(np.isfinite(corr), corr, np.nan)
    np.fill_diagonal(corr, 1.0)
    names = [p.name for p in parameters]
    unresolved = [
        {n: float(c) for n, c in zip(names, row, strict=True) if abs(c) > 1e-6} for row in vt[~seen]
    ]
    details = dict(at_bound=[n for n, b in zip(names, at_bound | pinned, strict=True) if b],
                   unresolved=unresolved, jacobian=jac_theta)  # fmt: skip
    return theta, se, corr, cov, s, chi2, details


def fit(
    scene,
    data: Measurements,
    parameters: Sequence,
    *,
    fixed: Mapping | None = None,
    residuals: ResidualSpec | Sequence[ResidualSpec] | None = None,
    control=None,
    max_iterations: int = 30,
    ftol: float = 1e-8,
    ctol: float | None = None,
    starts: int = 0,
    seed: int = 0,
    callback: Callable | None = None,
    optimiser: Callable | None = None,
    model_error: float | None = None,
    on_tolerance: Callable | None = None,
    replan: Callable | None = None,
    **simulate_options,
) -> FitResult:
    """Fit `parameters` of `scene` to `data`.

    **Arguments:**
    - `parameters`: specs for `make_parameters` (`"clearance=2e-4:1e-5:1e-3"`, tuples, or
      `FitParameter`s).
    - `fixed`: values of the other scene parameters (default: the scene's defaults).
    - `residuals`: a `ResidualSpec` (default: every sample, pointwise) or a sequence of them,
      fitted in turn (continuation: e.g. a short window or coarse block means first, each
      stage starting from the previous estimate). Uncertainties come from the last stage.
    - `control`: the model runs' `StepControl` (or a mapping of its fields overriding the
      scene's default, `batch.step_control`); `simulate_options` go to `simulate`.
    - `starts`, `seed`: global first stage (module docstring): `starts` Latin-hypercube
      points plus the guess, evaluated as one batch on the first residual stage; LM starts
      from the best. 0 (default) starts from the guess.
    - `callback(entry)`: called after every LM trial step with a history entry.
    - `optimiser`: the least-squares routine, with the signature and return value of
      `levenberg_marquardt` (the default); for comparing optimisers on the same stages.
    - `ftol`, `ctol`: a stage stops when an accepted step lowers ½|r|² by less than `ftol`
      relative or `ctol` absolute (default 1e-3 when the noise levels are given, so the
      residuals are in noise units and ½ is one standard error; else 0).
    - `model_error`: with noise levels given and an adaptive `control`, before every stage
      after the first the model's integration error is measured at the current estimate
      over the longest stage's samples (channels at rtol against rtol/10, in noise levels
      RMS: `choose_tolerance`'s rule, e.g. `MODEL_ERROR`) and rtol and atol are tightened
      by decades until it is at most `model_error` (`tolerance_at_estimate`: why). The
      record is the stage's `"tolerance"`; `on_tolerance(stage, record)` is called with it.
      None (default): every stage runs at `control`.
    - `replan(done, estimate, control)`: called before every stage after the first with the
      `ResidualSpec` just fitted, its estimate (`{name: value}`) and the step control; returns
      the stages to fit from here on (a non-empty sequence of `ResidualSpec`s within the
      longest stage's samples) or None to keep them (e.g. horizons from the impacts of the
      run at the estimate: `jaxdeploy fit`).

    **Returns:** a `FitResult`.
    """
    start = time.perf_counter()
    if starts < 0:
        raise ValueError(f"starts = {starts!r} is invalid: it must be ≥ 0")
    compiled, params, base, specs, comparisons = _model(
        scene, data, parameters, fixed, residuals, control, simulate_options
    )
    longest = max(comparisons, key=lambda c: c.n_save)
    z = internal_vector(params)
    history, stages, evaluations = [], [], 0
    model_initial = None
    control = compiled.control
    recheck = model_error is not None and control.rtol is not None and longest.noise_known
    k = 0
    while k < len(specs):
        tolerance = None
        if k > 0 and recheck:
            control, tolerance = tolerance_at_estimate(compiled, z, longest, control, model_error)
            tolerance["at"] = {
                p.name: float(p.to_physical(zk)) for p, zk in zip(params, z, strict=True)
            }
            if on_tolerance:
                on_tolerance(k, tolerance)
        if k > 0 and replan is not None:
            estimate = {p.name: float(p.to_physical(zk)) for p, zk in zip(params, z, strict=True)}
            _replace_stages(specs, comparisons, k, replan(specs[k - 1], estimate, control),
                            data, longest)  # fmt: skip
        spec, comparison = specs[k], comparisons[k]
        model = StageModel(compiled, comparison, control)
        if k == 0 and starts:
            candidates = np.vstack([z[None, :], latin_hypercube_starts(params, starts, seed)])
            costs = model.costs(candidates)
            if not np.isfinite(costs).any():
                raise RuntimeError(
                    f"no start point could be simulated (the guess and {starts} Latin-hypercube "
                    "points); change the bounds or the step control"
                )
            best = int(np.argmin(costs))
            evaluations += len(candidates)
            stages.append(
                dict(
                    spec=dict(kind="multistart", starts=starts, seed=seed),
                    iterations=0,
                    converged=True,
                    message=f"best of {len(candidates)} starts: "
                    + ("the guess" if best == 0 else f"point {best}"),
                    cost=float(costs[best]),
                    guess_cost=float(costs[0]),
                    start_params={
                        p.name: float(p.to_physical(zk))
                        for p, zk in zip(params, candidates[best], strict=True)
                    },
                    failed=int(np.sum(~np.isfinite(costs))),
                )
            )
            z = candidates[best]

        def report(entry, k=k):
            entry = dict(entry, stage=k)
            entry["params"] = {
                p.name: float(p.to_physical(zk)) for p, zk in zip(params, entry["z"], strict=True)
            }
            history.append(entry)
            if callback:
                callback(entry)

        z, r, jac, aux, info = (optimiser or levenberg_marquardt)(
            model,
            z,
            max_iterations=max_iterations,
            ftol=ftol,
            zmax=ZMAX,
            ctol=(1e-3 if comparison.noise_known else 0.0) if ctol is None else ctol,
            callback=report,
        )
        evaluations += info["evaluations"]
        if model_initial is None:
            model_initial = info["aux_initial"]
        stages.append(
            dict(
                spec=dict(
                    kind=spec.kind, windows=spec.windows, block=spec.block, width=spec.width
                ),  # fmt: skip
                iterations=info["iterations"],
                converged=info["converged"],
                message=info["message"],
                cost=0.5 * float(r @ r),
                rtol=control.rtol,
                **({"tolerance": tolerance} if tolerance else {}),
            )
        )
        k += 1
    theta, se, corr, cov, s, chi2, details = _curvature(params, z, r, jac, comparison.noise_known)
    names = [p.name for p in params]
    adequacy = assess(r, comparison.labels, len(params), comparison.noise_known)
    if comparison.spec.kind == "smooth":  # correlated by construction: no verdict
        adequacy.update(
            adequate=False,
            reasons=[
                "the last stage's residuals are smoothed "
                "(correlated by construction): end with --loss trajectory or block"
            ],
        )
    return FitResult(
        parameters=params,
        estimates=dict(zip(names, map(float, theta), strict=True)),
        standard_errors=dict(zip(names, map(float, se), strict=True)),
        correlation=corr,
        covariance=cov,
        singular_values=s,
        chi2=chi2,
        n_residuals=int(r.size),
        noise_known=comparison.noise_known,
        iterations=sum(st["iterations"] for st in stages),
        evaluations=evaluations,
        # The last stage decides: the earlier ones are continuation (smoothed channels, shorter
        # horizons) whose end only seeds the next, so a capped one is no verdict on the result.
        converged=stages[-1]["converged"],
        message=stages[-1]["message"],
        history=history,
        wall_time=time.perf_counter() - start,
        comparison=comparison,
        model_initial=model_initial,
        comparison_initial=comparisons[0],
        model_final=aux,
        stages=stages,
        adequacy=adequacy,
        model=compiled,
        z=np.asarray(z, dtype=float),
        control=control,
        **details,
    )


def _model(scene, data, parameters, fixed, residuals, control, simulate_options):
    """`(model, params, base, specs, comparisons)` of `fit`'s arguments: one compiled `Model`
    for every residual stage (over the longest stage's save times; the stages' tolerances
    are its data), the `FitParameter`s, every parameter's value, the stages and their
    `Comparison`s."""
    base = scene.resolve_params(fixed or {})
    params = make_parameters(scene, parameters, base)
    for p in params:
        scene.resolve_params({**base, p.name: p.guess})  # cross-checks at the guess
    if residuals is None:
        residuals = ResidualSpec()
    specs = [residuals] if isinstance(residuals, ResidualSpec) else list(residuals)
    comparisons = [Comparison(data, spec) for spec in specs]
    longest = max(comparisons, key=lambda c: c.n_save)
    model = Model(scene, params, base, longest.names, longest.ts, control, simulate_options)
    return model, params, base, specs, comparisons


def prepare_fit(
    scene,
    data: Measurements,
    parameters: Sequence,
    *,
    fixed: Mapping | None = None,
    residuals=None,
    control=None,
    on_traced: Callable | None = None,
    **simulate_options,
) -> bool:
    """Make the program `fit` with these arguments evaluates at every Levenberg–Marquardt
    step (the channels' Jacobian) ready without running it: traced, kept by the program
    cache and compiled (`Model.make_ready`). `control` need only have the structure of the
    fit's (its method and settings; the tolerances are data): `first_tolerance` gives it
    before `choose_tolerance` has chosen. For a second thread while the first chooses the
    tolerance and the horizons (`jaxdeploy fit`); `on_traced()` is called once the program
    is traced (XLA's compile follows, without Python's GIL). **Returns:** whether it was
    made (False: the program cache is off, or the model cannot be kept)."""
    model, params, *_ = _model(scene, data, parameters, fixed, residuals, control, simulate_options)
    return model.make_ready(internal_vector(params), on_traced=on_traced)


def _replace_stages(specs, comparisons, k, new, data, longest) -> None:
    """Replace `specs[k:]` (and their comparisons) by `replan`'s `new` stages, in place; the
    compiled model covers only `longest`'s save times, so no new stage may go beyond them."""
    if new is None:
        return
    new = list(new)
    made = [Comparison(data, spec) for spec in new]
    if not new or any(c.n_save > longest.n_save for c in made):
        raise ValueError(
            "replan must return at least one stage, each within the samples of the longest "
            f"stage given (up to t = {longest.t_end:g} s); got {new!r}"
        )
    specs[k:], comparisons[k:] = new, made


def tolerance_at_estimate(compiled: Model, z, comparison: Comparison, control, limit: float):
    """`(control, record)`: the loosest step control, from `control` down by decades, whose
    model at the internal point `z` moves by at most `limit` noise levels RMS over
    `comparison`'s samples at a 10x tighter tolerance (`_schedule.tighten`), evaluated with
    the fit's compiled model (its tolerances are data: nothing is compiled). Never looser than
    `control`.

    Why at the estimate, before each stage: the command chooses the tolerance at the start
    point (`choose_tolerance`), and a run's integration error there need not be that at the
    truth: impacts amplify it, and a start that bounces less accumulates less. On the 12 ms
    slider-crank with μ = 0.01 (docs/identification.md) the model at the start point (c_e =
    0.72, 13 impacts) moves by 0.022 σ RMS from rtol 1e-8 to 1e-9, at the first horizon's
    estimate (c and c_e within 0.04 % of the truth, μ 0.5 %) by 0.87 σ, and by 7e-5 σ from
    1e-9 to 1e-10. At rtol 1e-8 the model at the truth is then a round-off lottery: χ²/dof
    1.11, 1.13, 1.49 or 2.18 against the data for initial velocities 1e-15 apart (relative),
    where every run at 1e-9 gives 1.110; a fit at 1e-8 can end in a minimum that error made.
    The horizons' estimates approach the truth stage by stage, so a tolerance measured at
    each of them is the one the next, longer stage needs, before it fits."""
    n = comparison.n_save

    def evaluate(c):
        channels, _, ok = compiled(z, n, c)
        return ({name: v[:n] for name, v in channels.items()} if ok else None), None

    record = {"rtol": control.rtol, "limit": limit}
    first = evaluate(control)
    if first[0] is None:
        record.update(chosen_rtol=control.rtol, met=False, steps=[],
                      note="the run at the estimate failed")  # fmt: skip
        return control, record
    chosen, steps, met, _ = tighten(evaluate, comparison, control, first, limit)
    record.update(chosen_rtol=chosen.rtol, met=met, steps=steps)
    return chosen, record


def tolerance_check(result: FitResult, scene, fixed: Mapping, control) -> dict:
    """Rerun the model at the estimate with rtol and atol 10x tighter than the fit's `control`
    and report (a) the RMS change of the channels in noise levels and (b) the change of the
    estimates a refit at the tighter tolerance would make, from one Gauss–Newton step with
    the optimum's Jacobian (Δθ = −J⁺ r_tight: the refit's first iterate, accurate when the
    change is small), in standard errors. `reproducible` is false when either exceeds
    `REPRODUCIBLE` (1 noise level RMS, 1 standard error): the model's integration error is
    then not below the noise at the estimate, and the fit may have matched it (the change of
    the estimates is a linearisation: far beyond one standard error read it as "large", not
    as a number). Stored in `result.tolerance` and returned."""
    from ..batch import step_control
    from ._schedule import model_difference, run_channels

    cmp_ = result.comparison
    control = step_control(scene, control)
    params = {**scene.resolve_params(fixed), **result.estimates}
    record = {"rtol": control.rtol, "atol": control.atol}
    if control.rtol is None:
        record["note"] = "fixed step: no tolerance to tighten"
        result.tolerance = record
        return record
    tight = tighter(control)
    record.update(rtol_check=tight.rtol, atol_check=tight.atol)
    jac_tight = None
    if result.model is not None and result.z is not None:
        # One forward-mode evaluation of the fit's compiled model (its tolerance is data):
        # the channels and their Jacobian at the tighter tolerance.
        r_tight, jac_tight, y_tight, ok = StageModel(result.model, cmp_)(result.z, tight)
        y_tight = y_tight if ok else None
    else:
        y_tight, _ = run_channels(scene, params, cmp_.ts, cmp_.names, tight)
    if y_tight is None:
        record["note"] = "the run at the tighter tolerance failed"
        result.tolerance = record
        return record
    r_tight = cmp_.residuals_np(y_tight)
    delta = -np.linalg.lstsq(result.jacobian, r_tight, rcond=None)[0]
    se = np.array([result.standard_errors[n] for n in result.names])
    rms = model_difference(result.model_final, y_tight, cmp_)
    with np.errstate(invalid="ignore", divide="ignore"):
        moves = np.abs(delta / se)
    largest = float(np.max(np.where(np.isfinite(moves), moves, 0.0), initial=0.0))
    record.update(
        rms_model_change_over_sigma=rms,
        largest_estimate_change_in_standard_errors=largest,
        reproducible=bool(rms <= REPRODUCIBLE and largest <= REPRODUCIBLE),
        limit=REPRODUCIBLE,
        reduced_chi2_tight=float(r_tight @ r_tight) / max(r_tight.size - len(se), 1),
        estimate_change={n: float(d) for n, d in zip(result.names, delta, strict=True)},
        estimate_change_in_standard_errors={
            n: float(d / e) for n, d, e in zip(result.names, delta, se, strict=True)
        },
    )
    if jac_tight is not None:
        record.update(_derivative_check(result, r_tight, jac_tight))
    result.tolerance = record
    return record


def _derivative_check(result: FitResult, r_tight, jac_tight) -> dict:
    """The Jacobian's convergence at the estimate: the largest relative change of a parameter's
    column of ∂r/∂θ (2-norm; parameters at a bound left out) and of a standard error between
    the fit's tolerance and the 10x tighter one (`JACOBIAN_CHANGE`)."""
    _, se_tight, *_, details = _curvature(
        result.parameters, result.z, r_tight, jac_tight, result.noise_known
    )
    before, after = result.jacobian, details["jacobian"]
    changes, se_changes = {}, {}
    for k, name in enumerate(result.names):
        norm = float(np.linalg.norm(after[:, k]))
        if name in result.at_bound or not norm > 0:
            continue
        changes[name] = float(np.linalg.norm(after[:, k] - before[:, k])) / norm
        if math.isfinite(se_tight[k]) and se_tight[k] > 0:
            se_changes[name] = abs(result.standard_errors[name] / se_tight[k] - 1.0)
    change = max(changes.values(), default=0.0)
    return {
        "jacobian_change": change,
        "jacobian_change_by_parameter": changes,
        "standard_error_change": max(se_changes.values(), default=0.0),
        "standard_errors_check": {n: float(e) for n, e in zip(result.names, se_tight, strict=True)},
        "jacobian_limit": JACOBIAN_CHANGE,
        "derivatives_converged": bool(change <= JACOBIAN_CHANGE),
    }


def refit_until_reproducible(
    result: FitResult,
    scene,
    data: Measurements,
    *,
    fixed: Mapping,
    control,
    residuals: ResidualSpec | None = None,
    floor: float = RTOL_CHECK_FLOOR,
    max_iterations: int = 30,
    callback: Callable | None = None,
    on_stage: Callable | None = None,
    **simulate_options,
) -> tuple[FitResult, object, list[dict]]:
    """While `result` is not reproducible at the noise level or its Jacobian has not converged
    (`tolerance_check`: `reproducible`, `derivatives_converged`), refit at a 10x
    tighter rtol and atol, from its estimate, with its last residual stage (`residuals`), and
    check again; stop when a check passes, cannot run, or would need a run below `floor`.

    Why: the default tolerance is chosen at the start point (`choose_tolerance`), where the
    model error need not be that at the estimate. On the 12 ms slider-crank with μ = 0.01
    (docs/identification.md) the start point (c_e = 0.72, 13 impacts) changes by 0.13 σ RMS
    from rtol 1e-8 to 1e-9, the truth (25 impacts) by 4.7 σ: a fit at 1e-8 matches the
    integration error. The estimate of the refit at the tighter tolerance is the answer; each
    stage's check is what says whether that tolerance was tight enough.

    `result` must have been checked (`tolerance_check`). **Returns:** `(result, control,
    stages)`: the last refit (its `stages` and `history` continue the first fit's, its
    `iterations`, `evaluations` and `wall_time` add up; `model_initial` and the parameters'
    guesses stay the first fit's), its step control, and one record per refit (rtol,
    estimates, standard errors, χ²/dof, the check, trial steps, wall time). `on_stage(record)`
    is called after each."""
    import dataclasses

    from ..batch import step_control

    control = step_control(scene, control)
    spec = residuals if residuals is not None else result.comparison.spec
    records = []
    while (
        False in (result.reproducible, result.derivatives_converged)
        and control.rtol is not None
        and control.rtol * 0.01 >= floor * (1 - 1e-9)
    ):
        start = time.perf_counter()
        control = tighter(control)
        params = [dataclasses.replace(p, guess=result.estimates[p.name]) for p in result.parameters]
        offset = len(result.stages)

        def report(entry, offset=offset):
            entry = dict(entry, stage=entry["stage"] + offset)
            if callback:
                callback(entry)

        refit = fit(scene, data, params, fixed=fixed, residuals=spec, control=control,
                    max_iterations=max_iterations, callback=report,
                    **simulate_options)  # fmt: skip
        tolerance_check(refit, scene, fixed, control)
        for h in refit.history:
            h["stage"] += offset
        record = dict(
            rtol=control.rtol,
            atol=control.atol,
            estimates=refit.estimates,
            standard_errors=refit.standard_errors,
            reduced_chi2=refit.reduced_chi2,
            converged=refit.converged,
            adequate=refit.adequate,
            reproducible=refit.reproducible,
            derivatives_converged=refit.derivatives_converged,
            tolerance=refit.tolerance,
            iterations=refit.iterations,
            evaluations=refit.evaluations,
            wall_time_s=time.perf_counter() - start,
        )
        records.append(record)
        if on_stage:
            on_stage(record)
        stages = [dict(st, refit_rtol=control.rtol) for st in refit.stages]
        result = dataclasses.replace(
            refit,
            parameters=result.parameters,  # the user's guesses (the refit started elsewhere)
            stages=[*result.stages, *stages],
            history=[*result.history, *refit.history],
            iterations=result.iterations + refit.iterations,
            evaluations=result.evaluations + refit.evaluations,
            wall_time=result.wall_time + refit.wall_time,
            converged=refit.converged,
            model_initial=result.model_initial,
            comparison_initial=result.comparison_initial,
        )
    return result, control, records
