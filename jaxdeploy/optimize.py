"""Choosing parameters by gradients: a scene, an objective on its deployment, bounds, optax.

`DesignProblem` turns a scene and an `objectives.Objective` into a pure function of the design
parameters, J(x) (one simulation; the ideal-joint reference is computed once, at construction,
since it does not depend on the joint parameters). `optimize` minimises J over a box by a
bounded reparametrisation and optax; `evaluate_batch` evaluates J for many designs as one
vmapped run (`batch.simulate_batch`); `expected_objective` is J's expectation under a
`Scatter` (manufacturing tolerances) with its gradient, estimated from antithetic samples run
as one batch (`BatchObjective`).

Why sampled gradients for deploy_array: pathwise derivatives through the solver are exact for
the discrete map (fixed steps: AD equals central differences with h = 1e-4 in ln c), but after
contact chatter the objective is rough at small scales (its central differences at h = 1e-3
and 1e-2 differ from the local derivative by 30×, with other signs), and with adaptive steps the
pathwise derivative of post-lock features reaches 1e15 where differences over h = 0.1 give
O(1). The design question is about the trend over tens of percent of Ra and c, so the
objective optimised is the Gaussian-smoothed (or tolerance-averaged) J, whose gradient is
estimated by Stein's identity (`Scatter.estimate`); `optimize` also takes pathwise gradients
for smooth problems.

Bounds by reparametrisation: every parameter x_i ∈ [l_i, u_i] is a smooth
function of an unconstrained u_i,

    x_i = exp(ln l_i + (ln u_i − ln l_i) σ(u_i))   (l_i > 0: uniform in ln x, for Ra and c)
    x_i = l_i + (u_i − l_i) σ(u_i)                  (otherwise),

σ the logistic function; the optimiser sees only u, so every iterate is machinable.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import partial

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import _design_program
from .batch import run_scene, simulate_batch, step_control
from .objectives import Deployment, Objective, ideal_lock_time
from .scenes.base import Scene
from .solvers.step_control import StepControl

# Machinable ranges (SI): turned and reamed/ground hinge surfaces span Ra 0.2–6.3 µm (the
# ISO 1302 preferred series from 0.2 to 6.3), radial clearances of fitted pins 5–150 µm.
MACHINABLE = {"ra": (0.2e-6, 6.3e-6), "clearance": (5e-6, 150e-6)}


def machinable_bounds(scene: Scene, names) -> dict[str, tuple[float, float]]:
    """Default bounds of `names`: `*_ra` and `*_clearance` from `MACHINABLE`; others must be
    given explicitly."""
    out = {}
    for name in names:
        kind = name.rsplit("_", 1)[-1]
        if kind not in MACHINABLE:
            raise ValueError(
                f"parameter {name!r} has no default bounds; give them as {name}=LOW:HIGH"
            )
        out[name] = MACHINABLE[kind]
    return out


@dataclass(frozen=True)
class Box:
    """Bounds `{name: (low, high)}` and the reparametrisation x(u) (module docstring)."""

    bounds: Mapping[str, tuple[float, float]]

    def __post_init__(self):
        for name, (lo, hi) in self.bounds.items():
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise ValueError(
                    f"bounds of {name!r} = ({float(lo)!r}, {float(hi)!r}) are invalid: need "
                    "finite low < high"
                )

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.bounds)

    def to_params(self, u) -> dict:
        out = {}
        for i, (name, (lo, hi)) in enumerate(self.bounds.items()):
            s = jax.nn.sigmoid(u[i])
            if lo > 0:
                value = jnp.exp(math.log(lo) + (math.log(hi) - math.log(lo)) * s)
            else:
                value = lo + (hi - lo) * s
            out[name] = jnp.clip(value, lo, hi)  # exp(ln lo) may round below lo
        return out

    def from_params(self, x: Mapping) -> jax.Array:
        """Inverse of `to_params`; `x` must lie strictly inside the box."""
        u = []
        for name, (lo, hi) in self.bounds.items():
            value = float(x[name])
            if not lo < value < hi:
                raise ValueError(
                    f"start value {name} = {float(value)!r} must lie strictly inside ({lo}, {hi})"
                )
            if lo > 0:
                s = (math.log(value) - math.log(lo)) / (math.log(hi) - math.log(lo))
            else:
                s = (value - lo) / (hi - lo)
            u.append(math.log(s / (1 - s)))
        return jnp.asarray(u, dtype=float)


class DesignRuns:
    """The runs of a design problem, without its objective: `scene` with parameters `fixed` ∪ x
    over `n_save` equally spaced saved times to `t_end`, with `control` (a `StepControl`, or a
    mapping of its fields overriding the scene's default) and `adjoint` (None: reverse mode
    with checkpointing). `DesignProblem` evaluates its objective on these runs' outputs; made
    alone (it needs no ideal reference), it lets the design batch's runs be compiled while the
    reference runs (`prepare_batch`)."""

    def __init__(
        self,
        scene: Scene,
        t_end: float,
        *,
        n_save: int = 1601,
        fixed: Mapping | None = None,
        control: StepControl | Mapping | None = None,
        adjoint=None,
    ):
        self.scene, self.t_end, self.adjoint = scene, float(t_end), adjoint
        self.fixed = scene.resolve_params(fixed)
        self.control = control if isinstance(control, StepControl) else dict(control or {})
        self.ts = np.linspace(0.0, self.t_end, n_save)

    def params(self, x: Mapping) -> dict:
        unknown = [k for k in x if k not in self.fixed]
        if unknown:
            raise ValueError(
                f"unknown parameter {unknown[0]!r} for scene {self.scene.name!r}; valid: "
                + ", ".join(sorted(self.fixed))
            )
        return {**self.fixed, **x}

    def outputs(self, x: Mapping, trajectory=None, control=None):
        """`(channels, events, trajectory)` of design x: the scene's channels at the saved
        times and its event and episode outputs (`Scene.events`, `Scene.episode_outputs`),
        from `trajectory` if given, else a run with `control` if given, else the runs'."""
        params = self.params(x)
        if trajectory is None:
            options = {} if self.adjoint is None else {"adjoint": self.adjoint}
            control = self.control if control is None else control
            trajectory = run_scene(
                self.scene, params, self.t_end, ts=self.ts, control=control, **options
            )
        mechanism = self.scene.build(params)
        channels = self.scene.channels(mechanism, trajectory)
        events = {
            **self.scene.events(mechanism, trajectory),
            **self.scene.episode_outputs(mechanism, trajectory),
        }
        return channels, events, trajectory


class DesignProblem:
    """J(x) = objective(deployment of `scene` with parameters `fixed` ∪ x) for design parameters
    x (a dict of some of the scene's parameters).

    **Arguments:**
    - `scene`, `objective`, `t_end`, `n_save`: the run (saved times equally spaced).
    - `fixed`: other parameter values (defaults otherwise).
    - `ideal_scene`: the reference mechanism (default `type(scene)(ideal=True)` when the
      scene has that option; `None` otherwise: deviations are the raw channels).
    - `control`: a `StepControl` for every run (the design's and the ideal reference's), or a
      mapping of its fields overriding each scene's default.
    - `adjoint`: a diffrax adjoint for derivatives (default reverse mode with checkpointing;
      `diffrax.ForwardMode()` for forward mode, cheaper for a few parameters).

    The design runs are `self.runs` (`DesignRuns`, of the same arguments); the ideal
    reference is run here, at construction.
    """

    def __init__(
        self,
        scene: Scene,
        objective: Objective,
        t_end: float,
        *,
        n_save: int = 1601,
        fixed: Mapping | None = None,
        ideal_scene: Scene | None | str = "auto",
        control: StepControl | Mapping | None = None,
        lock_angle: float | None = None,
        adjoint=None,
    ):
        self.runs = DesignRuns(
            scene, t_end, n_save=n_save, fixed=fixed, control=control, adjoint=adjoint
        )
        self.objective = objective
        # The design runs' step control, resolved (what results record).
        self.step_control = step_control(scene, self.control)
        if ideal_scene == "auto":
            ideal_scene = type(scene)(ideal=True) if hasattr(scene, "ideal") else None
        self.ideal_scene = ideal_scene
        self.ideal = None
        self.ideal_status = "none"
        if ideal_scene is not None:
            shared = {k: v for k, v in self.fixed.items() if k in ideal_scene.params}
            p = ideal_scene.resolve_params(shared)
            trajectory = run_scene(ideal_scene, p, self.t_end, ts=self.ts, control=self.control)
            self.ideal_status = trajectory.status()
            if not trajectory.ok:
                raise RuntimeError(f"ideal reference run {self.ideal_status}")
            ideal_mechanism = ideal_scene.build(p)
            self.ideal = {
                k: np.asarray(v)
                for k, v in ideal_scene.channels(ideal_mechanism, trajectory).items()
            }
            ideal_events = ideal_scene.events(ideal_mechanism, trajectory)
        reference = self.ideal if self.ideal is not None else None
        if reference is not None and "lock_time" in ideal_events and lock_angle is None:
            # The located engagement of the ideal run (independent of the save grid).
            self.lock_time = float(ideal_events["lock_time"])
        elif reference is not None and "alpha" in reference and lock_angle is not None:
            self.lock_time = ideal_lock_time(self.ts, reference["alpha"], lock_angle)
        else:
            self.lock_time = 0.0
        if not math.isfinite(self.lock_time):
            raise ValueError(f"t_end = {self.t_end} s: the ideal mechanism does not lock by then")

    # The run settings are the runs' (`DesignRuns`).
    scene = property(lambda self: self.runs.scene)
    t_end = property(lambda self: self.runs.t_end)
    fixed = property(lambda self: self.runs.fixed)
    control = property(lambda self: self.runs.control)
    ts = property(lambda self: self.runs.ts)
    adjoint = property(lambda self: self.runs.adjoint)

    def params(self, x: Mapping) -> dict:
        return self.runs.params(x)

    def deployment(self, x: Mapping, trajectory=None, control=None, ideal=None):
        """`(Deployment, trajectory)` for design x (runs the simulation unless given, with
        `control` if given, else the problem's; the ideal reference is the problem's, or
        `ideal`: the same channels as arguments of a program, `_design_program`)."""
        channels, events, trajectory = self.runs.outputs(x, trajectory, control)
        return self.deployment_of(channels, events, ideal), trajectory

    def deployment_of(self, channels, events, ideal=None) -> Deployment:
        """The `Deployment` of a design run's outputs (`DesignRuns.outputs`) against the ideal
        reference (the problem's, or `ideal`, as in `deployment`)."""
        ideal = self.ideal if ideal is None else ideal
        return Deployment(self.ts, self.lock_time, channels, ideal, events)

    def evaluate(self, x: Mapping, control=None, ideal=None):
        """`(J, parts, ok)`: the objective, each term's feature, and the run's success flag
        (traceable in x; the design run with `control` if given, a `StepControl` whose
        tolerances may be traced: `optimize(..., control=...)`; `ideal` as in `deployment`)."""
        dep, trajectory = self.deployment(x, control=control, ideal=ideal)
        ok = trajectory.result == dfx.RESULTS.successful
        return self.objective(dep), self.objective.parts(dep), ok

    def __call__(self, x: Mapping):
        return self.evaluate(x)[0]


def evaluate_batch(problem: DesignProblem, cases) -> dict:
    """J and its parts for many designs as one vmapped run (`simulate_batch`).

    `cases`: `{name: (B,) values}` of design parameters. **Returns:** `{"objective": (B,),
    "parts": {label: (B,)}, "ok": (B,), "status": [str]}` (numpy).
    """
    batch = simulate_batch(
        problem.scene,
        cases,
        problem.t_end,
        fixed=problem.fixed,
        ts=problem.ts,
        control=problem.control,
    )
    varied = batch.varied

    def one(values, trajectory):
        x = dict(zip(varied, values, strict=True))
        dep, _ = problem.deployment(x, trajectory)
        return problem.objective(dep), problem.objective.parts(dep)

    values = tuple(jnp.asarray(batch.params[k]) for k in varied)
    if varied:
        objective, parts = jax.jit(jax.vmap(one))(values, batch.trajectory)
    else:
        objective, parts = jax.vmap(lambda tr: one((), tr))(batch.trajectory)
    return {
        "objective": np.asarray(objective),
        "parts": {k: np.asarray(v) for k, v in parts.items()},
        "ok": batch.ok,
        "status": batch.statuses(),
        "params": {k: np.asarray(v) for k, v in batch.params.items()},
    }


@dataclass(frozen=True)
class Scatter:
    """Gaussian scatter of design parameters: manufacturing tolerances (robust design) or a
    small numerical smoothing (nominal design), drawn with a seed.

    `relative`: `{name: s}`, x_i = x e^{s ξ_i} (log-normal: roughness is specified as a
    ratio); `absolute`: `{name: s}`, x_i = x + s ξ_i (a clearance tolerance in metres, s =
    tolerance/3 for a ±3σ band), floored at 1 % of x; ξ_i ~ N(0, 1). In the coordinate
    y = ln x (relative) or y = x (absolute) the scatter is y + s ξ. `nominal`: values of
    scattered parameters that are not design variables (e.g. a clearance fixed by the
    drawing but made with a tolerance).
    """

    relative: Mapping[str, float] = field(default_factory=dict)
    absolute: Mapping[str, float] = field(default_factory=dict)
    pairs: int = 4
    seed: int = 0
    nominal: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self):
        for name, s in {**self.relative, **self.absolute}.items():
            if not (math.isfinite(s) and s > 0):
                raise ValueError(f"scatter of {name!r} = {float(s)!r} is invalid: it must be > 0")
        if self.pairs < 1:
            raise ValueError(f"pairs = {self.pairs!r} is invalid: it must be ≥ 1")

    @property
    def names(self) -> tuple[str, ...]:
        return (*self.relative, *self.absolute)

    def scale(self, name: str) -> float:
        return self.relative.get(name, self.absolute.get(name))

    def draws(self, rng: np.random.Generator) -> dict[str, np.ndarray]:
        """Standard normal draws `{name: (pairs,)}`."""
        return {name: rng.standard_normal(self.pairs) for name in self.names}

    def antithetic(self, x: Mapping[str, float], draws: Mapping) -> dict[str, np.ndarray]:
        """The 2M designs x ⊕ (+s ξ_i) (first M) and x ⊕ (−s ξ_i) (last M), `{name: (2M,)}`."""
        out = {}
        for name, value in {**self.nominal, **x}.items():
            if name in self.relative:
                step = self.relative[name] * draws[name]
                out[name] = value * np.exp(np.concatenate([step, -step]))
            elif name in self.absolute:
                step = self.absolute[name] * draws[name]
                out[name] = np.maximum(value + np.concatenate([step, -step]), 0.01 * value)
            else:
                out[name] = np.full(2 * self.pairs, float(value))
        return out

    def estimate(self, values: np.ndarray, draws: Mapping) -> tuple[float, dict[str, float]]:
        """Mean and gradient of the smoothed objective from the 2M values at `antithetic`:

        J_s(y) = E_ξ[J(y + s ξ)],  Ĵ_s = (1/2M) Σ_i (J⁺_i + J⁻_i),
        ∂J_s/∂y_k ≈ (1/2M s_k) Σ_i (J⁺_i − J⁻_i) ξ_ik

        (Stein's identity ∇E[J(y + sξ)] = E[J(y + sξ) ξ]/s for Gaussian ξ, with antithetic
        pairs to cancel the even part of J; Nesterov & Spokoiny 2017, Found. Comput. Math.
        17:527). Unbiased for ∇J_s whatever the roughness of J at scales below s.
        """
        m = self.pairs
        plus, minus = values[:m], values[m:]
        gradient = {
            name: float(np.sum((plus - minus) * draws[name]) / (2 * m * self.scale(name)))
            for name in self.names
        }
        return float(np.mean(values)), gradient


class BatchObjective:
    """J for a batch of designs `{name: (B,)}` as one compiled vmapped run (the program is
    compiled once per batch size).

    `devices` (default: every JAX device, `jax.devices()`): the batch is split over them, each
    device running its share of the designs as one vmap (`jax.shard_map`, no communication),
    so that on a CPU split into one device per core (`jaxdeploy optimize`'s `--devices`) the
    shares run side by side. A batch that does not divide evenly is padded with copies of its
    last design, whose results are dropped. One device: a plain vmap. A vmapped case's last
    bits depend on its batch, so a design's J can differ by round-off between device counts.

    A `DesignProblem`'s batch is two module-level programs the program cache keeps
    (`_design_program`): the designs' runs (`problem.runs`), then the objective of their
    outputs (the ideal reference's channels its data): with the cache on, a second process
    with the same problem and devices traces nothing, and the runs' program can be made before
    the ideal reference exists (`prepare_batch`). Another `problem` (anything with
    `evaluate(x) -> (J, parts, ok)`) is traced in each process."""

    def __init__(self, problem: DesignProblem, devices=None):
        self.problem = problem
        self.devices = list(jax.devices() if devices is None else devices)
        if type(problem) is DesignProblem:
            # Module-level programs the program cache keeps (`_design_program`); a subclass
            # may evaluate otherwise than its description says: traced per instance below.
            runs = _design_program.runs_spec(problem.runs, problem.objective, self.devices)
            objective = _design_program.objective_spec(problem)
            self._run = partial(_design_program.call, runs, objective)
            return
        run = jax.vmap(problem.evaluate)
        if len(self.devices) > 1:
            mesh = jax.sharding.Mesh(np.array(self.devices), ("designs",))
            spec = jax.sharding.PartitionSpec("designs")
            run = jax.shard_map(run, mesh=mesh, in_specs=spec, out_specs=spec, check_vma=False)
        self._run = jax.jit(run)

    def __call__(self, designs: Mapping) -> tuple[np.ndarray, dict, np.ndarray]:
        designs = {k: np.asarray(v, dtype=float) for k, v in designs.items()}
        size = len(next(iter(designs.values())))
        inputs = _padded(designs, len(self.devices))
        values, parts, ok = self._run(inputs)
        parts = {k: np.asarray(v)[:size] for k, v in parts.items()}
        return np.asarray(values)[:size], parts, np.asarray(ok)[:size]


def _padded(designs: Mapping, devices: int) -> dict:
    """`designs` padded with copies of the last to a multiple of `devices` (`BatchObjective`)."""
    size = len(next(iter(designs.values())))
    pad = -(-size // devices) * devices - size
    return {k: np.concatenate([v, np.repeat(v[-1:], pad)]) for k, v in designs.items()}


def prepare_batch(
    runs: DesignRuns, objective: Objective, names, size: int, devices=None, on_traced=None
) -> bool:
    """Make the program of `BatchObjective`'s runs ready without running it, for a batch of
    `size` designs of the parameters `names` over `devices` (as `BatchObjective`'s), the
    runs `runs` and `objective` those of the `DesignProblem` to come: traced, kept by
    the program cache and compiled, so that the batch's first call runs it at once or waits
    for it. It needs no ideal reference: a second thread can make it while `DesignProblem`
    runs the reference (`jaxdeploy optimize`). `on_traced()` is called once it is traced
    (XLA's compile, which leaves Python's GIL free, follows). **Returns:** whether it was
    made (False: the program cache is off, or the runs cannot be described)."""
    from . import _program_cache

    devices = list(jax.devices() if devices is None else devices)
    designs = _padded({name: np.zeros(size) for name in names}, len(devices))
    spec = _design_program.runs_spec(runs, objective, devices)
    try:
        with _program_cache.ahead_of_time(), _program_cache.when_traced(on_traced):
            _design_program.run(spec, designs)
    except _program_cache.ProgramReady as ready:
        return ready.ready
    return False  # not reached: `ahead_of_time` raises before anything runs


def expected_objective(batch: Callable, x: Mapping, scatter: Scatter, rng) -> dict:
    """Ê[J] under `scatter` around x and its gradient (`Scatter.estimate`), from 2M designs
    evaluated as one batch. `batch(designs) -> (values, parts, ok)` (e.g. `BatchObjective`).
    **Returns:** `{"value", "gradient" (in y), "parts" (means), "ok", "values"}`."""
    draws = scatter.draws(rng)
    designs = scatter.antithetic(x, draws)
    values, parts, ok = batch(designs)
    value, gradient = scatter.estimate(values, draws)
    return {
        "value": value,
        "gradient": gradient,
        "parts": {k: float(np.mean(v)) for k, v in parts.items()},
        "ok": bool(np.all(ok)) and bool(np.all(np.isfinite(values))),
        "values": values,
        "designs": designs,
    }


@dataclass
class OptimizeResult:
    """History of an optimisation: per iteration the design, J, dJ/dx and the parts, and
    whether it succeeded (`status`)."""

    names: tuple[str, ...]
    x: list = field(default_factory=list)
    objective: list = field(default_factory=list)
    gradient: list = field(default_factory=list)
    parts: list = field(default_factory=list)
    wall_time: list = field(default_factory=list)
    ok: list = field(default_factory=list)
    stochastic: bool = False
    # "ok", or why the run stopped short (an iteration whose simulation, objective or gradient
    # was not finite: the last iterate is then that failed one).
    status: str = "ok"
    # The step tolerance search's record (`fit.DerivativeTolerance`) when `optimize` chose
    # the tolerance at which its pathwise gradient is converged; None otherwise.
    step_tolerance: object = None

    @property
    def best(self) -> int | None:
        """The iterate with the lowest objective among the successful ones (finite J and
        gradient), or None if none succeeded. For a smoothed objective the values compared
        are the per-iteration estimates of E[J] (2M samples each), so the choice carries
        their noise."""
        values = np.asarray(self.objective, dtype=float)
        good = np.asarray(self.ok, dtype=bool) & np.isfinite(values)
        if not good.any():
            return None
        return int(np.argmin(np.where(good, values, np.inf)))

    @property
    def optimum(self) -> dict[str, float] | None:
        """The best iterate's design (`best`), or None."""
        return None if self.best is None else dict(self.x[self.best])

    def to_json(self) -> dict:
        best = self.best
        return {
            "names": list(self.names),
            "status": self.status,
            "optimum": self.optimum,
            "optimum_objective": None if best is None else self.objective[best],
            "optimum_iteration": best,
            "last": self.x[-1] if self.x else None,
            "last_objective": self.objective[-1] if self.x else None,
            "stochastic": self.stochastic,
            "step_tolerance": self.step_tolerance and self.step_tolerance.to_json(),
            "history": [
                {
                    "iteration": i,
                    "x": self.x[i],
                    "objective": self.objective[i],
                    "gradient": self.gradient[i],
                    "parts": self.parts[i],
                    "ok": self.ok[i],
                    "wall_time_s": self.wall_time[i],
                }
                for i in range(len(self.x))
            ],
        }


def optimize(
    loss: Callable,
    x0: Mapping[str, float],
    bounds: Mapping[str, tuple[float, float]],
    *,
    steps: int = 20,
    learning_rate: float = 0.3,
    optimizer=None,
    smoothing: Scatter | None = None,
    callback: Callable | None = None,
    mode: str = "reverse",
    control: StepControl | None = None,
    derivative_change: float | None = None,
    progress: Callable | None = None,
) -> OptimizeResult:
    """Minimise over the box `bounds` from `x0` by gradient steps in the reparametrised u
    (module docstring), with optax.

    **Arguments:**
    - `loss`: with `smoothing=None`, x ↦ J or x ↦ `(J, parts, ok)` (as
      `DesignProblem.evaluate`), traceable in x and differentiated by JAX (pathwise).
      With a `smoothing` (`Scatter`), a batch function `designs ↦ (values, parts, ok)` (as
      `BatchObjective`): J is replaced by its Gaussian smoothing / expectation under the
      scatter and the gradient is estimated from 2M antithetic samples per iteration
      (`Scatter.estimate`), fresh draws each iteration from `smoothing.seed` (a stochastic
      gradient method). This is the robust design when the scatter is the manufacturing
      tolerance, and the remedy for objectives that are rough below some scale.
    - `steps`: number of objective/gradient evaluations.
    - `optimizer`: an optax `GradientTransformation` (default `optax.adam(learning_rate)`).
    - `callback(i, result)`: called after each evaluation (progress display).
    - `mode`: how a pathwise gradient (`smoothing=None`) is taken: `"reverse"`
      (`jax.value_and_grad`; the loss's runs need a reverse-capable adjoint, diffrax's
      default) or `"forward"` (`jax.jacfwd`, one tangent per parameter; the loss's runs may
      use `diffrax.ForwardMode()`, which reverse mode cannot differentiate).
      `jaxdeploy.fit.gradient_mode` gives the cheaper one for a parameter count.
    - `control` (pathwise only): a `StepControl`; `loss` is then called as `loss(x, control)`
      (as `DesignProblem.evaluate`), the control's tolerances data of the compiled gradient
      (`solvers.tolerances_as_data`: one program whatever the tolerance).
    - `derivative_change` (with `control`): first choose the step tolerance at which the
      gradient at `x0` is converged, the loosest rtol from `control`'s down whose gradient
      changes by at most this fraction at rtol/10 (`fit.converged_tolerance`, the rule
      `fit.derivative_tolerance` and `jaxdeploy gradcheck` use; its record in
      `result.step_tolerance`), and optimise at it: a derivative through an adaptive run
      needs a tighter tolerance than its value (deploy_array's lock time at rtol 1e-6: AD
      0.8 % off in the clearance). Each tighter tolerance tried costs one gradient
      evaluation, no compile. None: optimise at `control` as given.
    - `progress(message)`: told each step of the tolerance search.

    **Returns:** `OptimizeResult`; `.optimum` is the best successful iterate (lowest J),
    `.status` "ok" or, when an iteration's simulation, J or gradient is not finite, a message
    naming it: the run stops there (a step from a NaN gradient would make every later
    iterate NaN) and returns what it found before.
    """
    import optax

    box = Box(dict(bounds))
    optimizer = optax.adam(learning_rate) if optimizer is None else optimizer
    x_of_u = jax.jit(box.to_params)
    # dx/du (diagonal: each x_i depends on u_i only).
    dx_du = jax.jit(
        lambda w: jnp.diag(jax.jacfwd(lambda v: jnp.stack(list(box.to_params(v).values())))(w))
    )

    if smoothing is None:
        if mode not in ("reverse", "forward"):
            raise ValueError(f"mode = {mode!r} is invalid; valid: reverse, forward")
        if control is None:
            value_and_grad = jax.jit(_value_and_grad(_reduced(loss, box), mode))
        else:
            value_and_grad, step_tolerance = _at_converged_tolerance(
                loss, box, x0, mode, control, derivative_change, progress
            )
    else:
        unknown = [n for n in smoothing.names if n not in (*box.names, *smoothing.nominal)]
        if unknown:
            raise ValueError(
                f"smoothing: {unknown[0]!r} is neither a design parameter nor in its nominal"
            )
        if control is not None:
            raise ValueError("control is for pathwise gradients (smoothing=None)")
        rng = np.random.default_rng(smoothing.seed)

    u = box.from_params(x0)
    state = optimizer.init(u)
    result = OptimizeResult(box.names, stochastic=smoothing is not None)
    if smoothing is None and control is not None:
        result.step_tolerance = step_tolerance
    for i in range(steps):
        start = time.perf_counter()
        x = {k: float(v) for k, v in x_of_u(u).items()}
        jac = np.asarray(dx_du(u))
        if smoothing is None:
            (value, (parts, ok)), grad_u = value_and_grad(u)
            grad_u = np.asarray(grad_u)
            grad_x = grad_u / jac
            value, ok = float(value), bool(ok)
            parts = {k: float(v) for k, v in parts.items()}
        else:
            est = expected_objective(loss, x, smoothing, rng)
            value, ok, parts = est["value"], est["ok"], est["parts"]
            # ∂J/∂y → ∂J/∂x (y = ln x for relative scatter) → ∂J/∂u; unsmoothed names: 0.
            grad_x = np.array(
                [
                    est["gradient"].get(n, 0.0) / (x[n] if n in smoothing.relative else 1.0)
                    for n in box.names
                ]
            )
            grad_u = grad_x * jac
        ok = ok and bool(np.all(np.isfinite(grad_u)))
        result.x.append(x)
        result.objective.append(value)
        result.gradient.append(dict(zip(box.names, grad_x.tolist(), strict=True)))
        result.parts.append(parts)
        result.ok.append(ok)
        result.wall_time.append(time.perf_counter() - start)
        if not (ok and math.isfinite(value)):
            result.ok[-1] = False
            result.status = (
                f"failed at iteration {i} (x = {x}): the simulation, the objective or its "
                "gradient is not finite"
            )
        if callback is not None:
            callback(i, result)
        if i == steps - 1 or result.status != "ok":
            break
        updates, state = optimizer.update(jnp.asarray(grad_u), state, u)
        u = optax.apply_updates(u, updates)
    return result


def _reduced(loss: Callable, box: Box) -> Callable:
    """`(u, [c]) ↦ (J, (parts, ok))` of `loss(x(u)[, c])` returning J or `(J, parts, ok)`."""

    def reduced(u, *c):
        out = loss(box.to_params(u), *c)
        if not isinstance(out, tuple):
            out = (out, {}, jnp.asarray(True))
        value, parts, ok = out
        return value, (parts, ok)

    return reduced


def _at_converged_tolerance(loss, box, x0, mode, control, fraction, progress):
    """`(value_and_grad, tolerance)`: `u ↦ ((J, (parts, ok)), ∂J/∂u)` of `loss(x, control)`
    at the step control chosen by `fit.converged_tolerance` from `control` (at `x0`), or at
    `control` when `fraction` is None (`tolerance` then None); one compiled program for every
    tolerance tried and the optimisation."""
    from .fit import converged_tolerance
    from .solvers import tolerances_as_data

    program = _kept_gradient(loss, box, mode)
    if program is None:
        reduced = _reduced(loss, box)

        def gradient_at(c, u):
            return _value_and_grad(lambda v: reduced(v, c), mode)(u)

        program = tolerances_as_data(gradient_at)
    if fraction is None:
        return partial(program, control), None
    u0 = box.from_params(x0)

    def gradient(c):
        _, grad_u = program(c, u0)
        return dict(zip(box.names, map(float, np.asarray(grad_u)), strict=True))

    found = converged_tolerance(gradient, control, fraction=fraction, progress=progress)
    return partial(program, found.control), found


def _kept_gradient(loss, box: Box, mode: str):
    """`(control, u) ↦ ((J, (parts, ok)), ∂J/∂u)` as `_at_converged_tolerance`'s program, for
    `loss` the `evaluate` of a `DesignProblem` (not a subclass): a module-level program
    (`_design_gradient`) the program cache keeps (`_design_program.gradient_spec`); None for
    another loss (a closure, traced in each process)."""
    from .solvers import split_tolerances

    problem = getattr(loss, "__self__", None)
    if type(problem) is not DesignProblem or loss.__func__ is not DesignProblem.evaluate:
        return None
    specs = {}

    def program(control, u):
        structure, rtol, atol = split_tolerances(control)
        if structure not in specs:
            specs[structure] = _design_program.gradient_spec(problem, box, mode, structure)
        return _design_program.call_gradient(_design_gradient, specs[structure], rtol, atol, u)

    return program


@eqx.filter_jit
def _design_gradient(design, rtol, atol, u, ideal):
    """`((J, (parts, ok)), ∂J/∂u)` of the design problem's J at x(u) (`_reduced`) by the
    design's mode, the step control of its structure with tolerances `rtol`, `atol`, the
    ideal reference's channels `ideal` (`_design_program.gradient_spec`)."""
    from .solvers import with_tolerances

    problem, box, mode, structure = design.static.value
    control = with_tolerances(structure, rtol, atol)
    reduced = _reduced(lambda x, c: problem.evaluate(x, c, ideal=ideal), box)
    return _value_and_grad(lambda v: reduced(v, control), mode)(u)


def _value_and_grad(reduced: Callable, mode: str) -> Callable:
    """`u ↦ ((J, aux), ∂J/∂u)` of `reduced(u) = (J, aux)` by reverse or forward mode."""
    if mode == "reverse":
        return jax.value_and_grad(reduced, has_aux=True)

    def value_as_aux(u):
        value, aux = reduced(u)
        return value, (value, aux)

    jacobian = jax.jacfwd(value_as_aux, has_aux=True)

    def forward(u):
        grad, out = jacobian(u)
        return out, grad

    return forward
