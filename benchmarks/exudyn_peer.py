"""Exudyn peer for the work–precision benchmark: the Flores slider-crank in Exudyn, solved by
Exudyn's own generalized-α.

Exudyn (J. Gerstmayr, *Multibody Syst. Dyn.* 2023; `pip install exudyn`, tested with 1.13.6)
is a C++ multibody code with a Python interface. The model, from its item library
(docs: https://exudyn.readthedocs.io, "Items" and "Solver"; the shipped example
`Examples/SliderCrank.py` builds an ideal slider-crank the same way):

* crank, rod and slider: three `NodeRigidBody2D` + `ObjectRigidBody2D` (coordinates x, y, θ of
  each centre of mass, reference configuration zero, so node coordinates *are* our q),
  gravity by `LoadMassProportional` on each body;
* ground–crank and crank–rod pins: `ObjectJointRevolute2D` between `MarkerBodyPosition`s;
* crank drive θ₁ = ω t: `ObjectConnectorCoordinate` on θ₁ with `velocityLevel=True` and
  offset ω (θ̇₁ = ω; with θ₁(0) = 0 and a constant ω this is θ₁ = ω t, and no Python
  function is called by the solver);
* slider on its guide: `ObjectConnectorCoordinate` fixing y₃ and θ₃ (as our `Prismatic`);
* rod–slider joint: (a) ideal, `ObjectJointRevolute2D`; (b) with clearance, an
  `ObjectConnectorCartesianSpringDamper` between the bearing centre (slider) and the journal
  centre (rod small end) whose `springForceUserFunction` returns the contact force.

That is 9 coordinates and 9 (ideal) or 7 (clearance) constraints, as jaxdeploy's model.

**Contact law (b)** — the classical Lankarani & Nikravesh (1990) law, eq. 17, with the
scene's Hertz stiffness: with e = r_Pj − r_Pi (the connector's displacement, marker 1 minus
marker 0), |e| = sqrt(e·e + ε²) (ε = 1e-12 m), n = e/|e|, δ = |e| − c, δ̇ = ė·n,

    F_N = max(0, K δ^{3/2} (1 + χ δ̇ / v_eff)),  v_eff = max(v⁻, v_floor)   (δ > 0)

K = (4/3) E* sqrt(R_j R_b / c), E* = E / (2(1 − ν²)) (Hertz, same material; Flores &
Ambrósio 2004, eq. 20), χ = 3(1 − c_e²)/4, v⁻ the approach speed δ̇ at the onset of contact,
held for the whole contact (the classical rule), v_floor = 1e-4 m/s (as jaxdeploy's
`DEFAULT_IMPACT_VELOCITY_FLOOR`). The force on the journal is −F_N n; the model applies it at
the journal *centre*, jaxdeploy at the contact point P_j + R_j n: without friction the force
passes through both points along n, so the moments about every body's centre are identical.

**v⁻ memory** — Exudyn has no memory variable for a user-function force, so it is kept in
Python and updated by a `PostStepUserFunction` (called once after every accepted step, with
the state at the step's end): a step that ends in contact after starting out of it sets v⁻ to
δ̇ at the onset, located on the cubic Hermite interpolant of the step's end values (e, ė)
(Exudyn has no event location); v⁻ is then held until a step ends out of contact. Within the
step in which a contact begins (memory still out of contact) the force uses max(δ̇, 0) as v⁻.

**Step size** — Exudyn's generalized-α has no error-controlled step size (its
`automaticStepSize` applies to the explicit solvers with error estimates, e.g. DOPRI5); only
`adaptiveStep`, which halves a step whose Newton iteration fails. Fixed steps are therefore the
only Exudyn configurations, run with `adaptiveStep = False` so that a step is never silently
repeated (a Newton failure is reported as a failed run, as in jaxdeploy's fixed-step mode).
Everything else is Exudyn's default (modified Newton, relative tolerance 1e-8).

**Cost** — with `force_function="python"` the force is a Python function, called for every
residual and every Jacobian column of the connector; with `"symbolic"` the same law is an
Exudyn symbolic user function (`exudyn.symbolic`, recorded once from Python and evaluated in
C++; v⁻ is a named symbolic variable). Either way the post-step memory update is one Python
call per step. That is how an Exudyn user writes a contact law Exudyn does not provide (its own
contact models use a linear or a Hertz-like law without the restitution-calibrated damping and
v⁻ memory).
"""

from __future__ import annotations

import math
import os
import sys
import time
from dataclasses import dataclass

import numpy as np

VELOCITY_FLOOR = 1e-4  # m/s, as jaxdeploy.contact.damping.DEFAULT_IMPACT_VELOCITY_FLOOR
ECCENTRICITY_SMOOTHING = 1e-12  # m, as RevoluteClearance.eccentricity_smoothing


# How the clearance force reaches Exudyn: a Python user function, or the same law as an Exudyn
# symbolic user function (evaluated in C++; `ExudynSliderCrank._use_symbolic_force`).
FORCE_FUNCTIONS = ("python", "symbolic")


class ExudynUnavailable(RuntimeError):
    """Exudyn is not installed (the `bench` extra); the Exudyn peer is skipped."""


def import_exudyn():
    """`(exudyn, exudyn.itemInterface)`, or `ExudynUnavailable` with the install hint."""
    try:
        import exudyn
        import exudyn.itemInterface as items
    except ImportError as err:  # pragma: no cover - depends on the environment
        raise ExudynUnavailable(
            f"exudyn is not importable ({err}); the Exudyn peer is skipped. Install it with "
            "`pip install -e .[bench]` (or `pip install exudyn`)."
        ) from err
    return exudyn, items


def exudyn_available() -> bool:
    try:
        import_exudyn()
    except ExudynUnavailable:
        return False
    return True


def exudyn_version() -> str:
    exudyn, _ = import_exudyn()
    return exudyn.__version__


_GRID, _NEWTON = 16, 10  # as jaxdeploy.mechanism._step_eccentricity


class _EccentricityStep:
    """e over one step as the cubic Hermite interpolant of `(e₀, ė₀)`, `(e₁, ė₁)`, s ∈ [0, 1],
    with δ = |e|_ε − c and δ̇ = ė·e/|e|_ε on it; the onset (last upward crossing of δ = level)
    bracketed on 17 samples and refined by a safeguarded Newton iteration
    (`jaxdeploy.mechanism._step_eccentricity.StepEccentricity`, written again in plain Python
    for the post-step function):

        e(s) = e₀ + h (a s + c₁ s²/2 + c₂ s³/3),   c₁ = 6m − 4a − 2b,   c₂ = 3a + 3b − 6m,
        a = ė₀, b = ė₁, m = (e₁ − e₀)/h."""

    def __init__(self, e0, rate0, e1, rate1, step, clearance):
        mean = [(e1[i] - e0[i]) / step for i in range(2)]
        self.e0, self.a, self.h, self.clearance = e0, rate0, step, clearance
        self.c1 = [6.0 * mean[i] - 4.0 * rate0[i] - 2.0 * rate1[i] for i in range(2)]
        self.c2 = [3.0 * rate0[i] + 3.0 * rate1[i] - 6.0 * mean[i] for i in range(2)]

    def _derivatives(self, s):
        h, a, c1, c2 = self.h, self.a, self.c1, self.c2
        u = [self.e0[i] + h * (a[i] * s + c1[i] * s * s / 2 + c2[i] * s**3 / 3) for i in range(2)]
        u1 = [h * (a[i] + c1[i] * s + c2[i] * s * s) for i in range(2)]
        u2 = [h * (c1[i] + 2.0 * c2[i] * s) for i in range(2)]
        u3 = [2.0 * h * c2[i] for i in range(2)]
        return u, u1, u2, u3

    @staticmethod
    def _dot(x, y):
        return x[0] * y[0] + x[1] * y[1]

    def _radius(self, u):
        return math.sqrt(self._dot(u, u) + ECCENTRICITY_SMOOTHING**2)

    def penetration(self, s):
        return self._radius(self._derivatives(s)[0]) - self.clearance

    def rate(self, s):
        u, u1, _, _ = self._derivatives(s)
        return self._dot(u, u1) / (self.h * self._radius(u))

    def crossing(self, level):
        """s where δ(s) rises through `level` for the last time (δ₀ ≤ level < δ₁)."""
        k = max([j for j in range(_GRID) if self.penetration(j / _GRID) <= level], default=0)
        lo, hi = k / _GRID, (k + 1) / _GRID
        x = 0.5 * (lo + hi)
        for _ in range(_NEWTON + 1):
            f = self.penetration(x) - level
            u, u1, _, _ = self._derivatives(x)
            slope = self._dot(u, u1) / self._radius(u)
            lo, hi = (x, hi) if f <= 0 else (lo, x)
            newton = x - f / slope if slope > 0 else -1.0
            x = newton if lo < newton < hi else 0.5 * (lo + hi)
        return x


@dataclass
class ExudynRun:
    """One Exudyn solve: states at the requested times and the solver's counters."""

    q: np.ndarray  # (len(ts), 9)
    v: np.ndarray  # (len(ts), 9)
    steps: int
    rejected: int  # always 0: fixed steps, adaptiveStep off (no step is repeated)
    newton_iterations: int
    jacobians: int
    wall: float  # seconds in SolveDynamic
    ok: bool
    message: str


class ExudynSliderCrank:
    """The slider-crank of `jaxdeploy.scenes.SliderCrank` built in Exudyn (module docstring).

    **Arguments:**
    - `params`: the scene's resolved parameters (frictionless, smooth: μ = σ = 0 only).
    - `q0`, `v0`: initial coordinates and velocities (crank, rod, slider; x, y, θ each), e.g.
      from `SliderCrank.initial_state`.
    - `ideal`: an ideal rod–slider revolute joint instead of the clearance contact.
    - `rho_inf`: spectral radius at infinity of Exudyn's generalized-α.
    - `force_function`: "python" (a Python user function) or "symbolic" (Exudyn's symbolic
      user function, evaluated in C++; the v⁻ memory update stays a Python post-step call).
    """

    def __init__(self, params, q0, v0, *, ideal=False, rho_inf=0.8, force_function="python"):
        p = {k: float(v) for k, v in params.items()}
        if force_function not in FORCE_FUNCTIONS:
            raise ValueError(
                f"force_function = {force_function!r} is invalid; valid: "
                + ", ".join(FORCE_FUNCTIONS)
            )
        self.force_function = force_function
        if not ideal and (p.get("friction_coefficient", 0.0) != 0 or p.get("sigma", 0.0) != 0):
            raise ValueError(
                "ExudynSliderCrank models the frictionless, smooth (Hertz) contact only: "
                f"friction_coefficient = {p.get('friction_coefficient')!r} and sigma = "
                f"{p.get('sigma')!r} must both be 0"
            )
        if not 0.0 <= rho_inf <= 1.0:
            raise ValueError(f"rho_inf = {rho_inf!r} is invalid: it must be in [0, 1]")
        self.exu, self.items = import_exudyn()
        self.params, self.ideal, self.rho_inf = p, ideal, rho_inf
        self.q0 = np.asarray(q0, dtype=float).reshape(9)
        self.v0 = np.asarray(v0, dtype=float).reshape(9)
        rj, c = p["journal_radius"], p["clearance"]
        e_star = p["youngs_modulus"] / (2.0 * (1.0 - p["poisson_ratio"] ** 2))
        self.stiffness = 4.0 / 3.0 * e_star * math.sqrt(rj * (rj + c) / c)
        self.chi = 0.75 * (1.0 - p["restitution"] ** 2)
        self.clearance = c
        self.memory = {}
        # (end time of the step in which a contact ended, v⁻ of that contact), per contact:
        # the largest approach speed reached, including a peak inside the last step.
        self.contact_history = []
        self._build()

    # --- model -----------------------------------------------------------------------------

    def _build(self):
        exu, it = self.exu, self.items
        p = self.params
        r, ell = p["crank_length"], p["rod_length"]
        self.container = exu.SystemContainer()
        mbs = self.mbs = self.container.AddSystem()
        ground = mbs.AddObject(it.ObjectGround())
        ground_node = mbs.AddNode(it.NodePointGround())
        self.nodes, bodies = [], []
        inertia = [
            (p["crank_mass"], p["crank_inertia"]),
            (p["rod_mass"], p["rod_inertia"]),
            (p["slider_mass"], p["slider_inertia"]),
        ]
        for k, (mass, moment) in enumerate(inertia):
            node = mbs.AddNode(
                it.NodeRigidBody2D(
                    referenceCoordinates=[0.0, 0.0, 0.0],
                    initialCoordinates=list(self.q0[3 * k : 3 * k + 3]),
                    initialVelocities=list(self.v0[3 * k : 3 * k + 3]),
                )
            )
            body = mbs.AddObject(it.ObjectRigidBody2D(mass=mass, inertia=moment, nodeNumber=node))
            marker = mbs.AddMarker(it.MarkerBodyMass(bodyNumber=body))
            mbs.AddLoad(
                it.LoadMassProportional(markerNumber=marker, loadVector=[0, -p["gravity"], 0])
            )
            self.nodes.append(node)
            bodies.append(body)
        crank, rod, slider = bodies

        def point(body, x):
            return mbs.AddMarker(it.MarkerBodyPosition(bodyNumber=body, localPosition=[x, 0, 0]))

        def coordinate(node, index):
            return mbs.AddMarker(it.MarkerNodeCoordinate(nodeNumber=node, coordinate=index))

        mbs.AddObject(
            it.ObjectJointRevolute2D(markerNumbers=[point(ground, 0.0), point(crank, -r / 2)])
        )
        mbs.AddObject(
            it.ObjectJointRevolute2D(markerNumbers=[point(crank, r / 2), point(rod, -ell / 2)])
        )
        fixed = coordinate(ground_node, 0)
        for index in (1, 2):  # slider y and θ
            mbs.AddObject(
                it.ObjectConnectorCoordinate(
                    markerNumbers=[fixed, coordinate(self.nodes[2], index)]
                )
            )
        mbs.AddObject(
            it.ObjectConnectorCoordinate(
                markerNumbers=[fixed, coordinate(self.nodes[0], 2)],
                offset=p["crank_speed"],
                velocityLevel=True,
            )
        )
        bearing, journal = point(slider, 0.0), point(rod, ell / 2)
        if self.ideal:
            mbs.AddObject(it.ObjectJointRevolute2D(markerNumbers=[bearing, journal]))
        else:
            self.contact_object = mbs.AddObject(
                it.ObjectConnectorCartesianSpringDamper(
                    markerNumbers=[bearing, journal],
                    stiffness=[0.0, 0.0, 0.0],
                    damping=[0.0, 0.0, 0.0],
                    springForceUserFunction=self._contact_force,
                )
            )
            if self.force_function == "symbolic":
                self._use_symbolic_force()
            mbs.SetPostStepUserFunction(self._after_step)
        self.sensors = [
            (
                mbs.AddSensor(
                    it.SensorNode(
                        nodeNumber=node,
                        storeInternal=True,
                        writeToFile=False,
                        outputVariableType=kind,
                    )
                )
            )
            for kind in (exu.OutputVariableType.Coordinates, exu.OutputVariableType.Coordinates_t)
            for node in self.nodes
        ]
        mbs.Assemble()
        self.ode2_index = [mbs.GetNodeODE2Index(n) for n in self.nodes]
        if self.ode2_index != [0, 3, 6]:
            raise RuntimeError(f"unexpected Exudyn coordinate layout {self.ode2_index}")

    # --- contact ---------------------------------------------------------------------------

    def geometry(self, e, e_dot):
        """`(δ, δ̇, n)` from the eccentricity e = r_Pj − r_Pi and its rate."""
        norm_e = math.sqrt(e[0] * e[0] + e[1] * e[1] + ECCENTRICITY_SMOOTHING**2)
        n = (e[0] / norm_e, e[1] / norm_e)
        return norm_e - self.clearance, e_dot[0] * n[0] + e_dot[1] * n[1], n

    def normal_force(self, delta, rate):
        """F_N(δ, δ̇) with the current memory (module docstring)."""
        if delta <= 0.0:
            return 0.0
        # Within the step in which the contact begins the memory has no onset yet: δ̇ stands in.
        v_minus = self.memory["impact_velocity"] if self.memory["in_contact"] else max(rate, 0.0)
        v_eff = max(v_minus, VELOCITY_FLOOR)
        return max(0.0, self.stiffness * delta**1.5 * (1.0 + self.chi * rate / v_eff))

    def _contact_force(self, mbs, t, item, displacement, velocity, stiffness, damping, offset):
        # Connector convention: the returned vector f acts as −f on marker 1 (journal) and +f on
        # marker 0 (bearing), like a spring force k Δp; the journal gets −F_N n.
        delta, rate, n = self.geometry(displacement, velocity)
        fn = self.normal_force(delta, rate)
        return [fn * n[0], fn * n[1], 0.0]

    def _use_symbolic_force(self):
        """Replace the Python force function by the same law as an Exudyn symbolic user
        function (an expression tree recorded from Python once and evaluated in C++), with v⁻
        as a named symbolic variable that the post-step function sets. `max(0, δ)^{3/2}` is
        written `δ₊ sqrt(δ₊)`, which equals K δ^{3/2} for δ > 0 and 0 otherwise."""
        from exudyn.advancedUtilities import CreateSymbolicUserFunction

        esym = self.exu.symbolic
        v_minus = esym.Real(f"vMinus{id(self)}", 0.0)
        held = esym.Real(f"inContact{id(self)}", 0.0)  # 1 in contact: v⁻ held, else δ̇
        stiffness, chi, clearance = self.stiffness, self.chi, self.clearance

        def force(mbs, t, item, u, v, k, d, offset):
            norm = esym.sqrt(u[0] * u[0] + u[1] * u[1] + ECCENTRICITY_SMOOTHING**2)
            n0, n1 = u[0] / norm, u[1] / norm
            rate = v[0] * n0 + v[1] * n1
            v_m = held * v_minus + (1.0 - held) * esym.max(rate, 0.0)
            v_eff = esym.max(v_m, VELOCITY_FLOOR)
            inside = esym.max(norm - clearance, 0.0)
            fn = esym.max(0.0, stiffness * inside * esym.sqrt(inside) * (1.0 + chi * rate / v_eff))
            return [fn * n0, fn * n1, 0.0]

        function = CreateSymbolicUserFunction(
            self.mbs,
            force,
            "springForceUserFunction",
            itemTypeName="ObjectConnectorCartesianSpringDamper",
        )
        self.mbs.SetObjectParameter(self.contact_object, "springForceUserFunction", function)
        # Both must outlive the solver (Exudyn keeps a reference to the expression tree only).
        self._symbolic = (v_minus, function, held)

    def _memory_changed(self):
        if self.force_function == "symbolic":
            self._symbolic[0].SetValue(float(self.memory["impact_velocity"]))
            self._symbolic[2].SetValue(1.0 if self.memory["in_contact"] else 0.0)

    def eccentricity(self, q, v):
        """e and ė from node coordinates (rod small end minus slider centre)."""
        half = 0.5 * self.params["rod_length"]
        c, s = math.cos(q[5]), math.sin(q[5])
        e = (q[3] + half * c - q[6], q[4] + half * s - q[7])
        e_dot = (v[3] - half * s * v[5] - v[6], v[4] + half * c * v[5] - v[7])
        return e, e_dot

    def _reset_memory(self):
        e, e_dot = self.eccentricity(self.q0, self.v0)
        delta, rate, _ = self.geometry(e, e_dot)
        self.memory = {
            "in_contact": delta > 0.0,
            "impact_velocity": max(rate, 0.0),
            "penetration": delta,
            "penetration_rate": rate,
            "eccentricity": e,
            "eccentricity_rate": e_dot,
            "time": 0.0,
        }
        self.contact_history = []
        self._memory_changed()

    def _after_step(self, mbs, t):
        """The classical rule's memory after the accepted step that ended at t (module
        docstring): v⁻ = δ̇ at an onset inside the step, held in contact, 0 out of it."""
        current = self.exu.ConfigurationType.Current
        q = mbs.systemData.GetODE2Coordinates(configuration=current)
        v = mbs.systemData.GetODE2Coordinates_t(configuration=current)
        e, e_dot = self.eccentricity(q, v)
        delta, rate, _ = self.geometry(e, e_dot)
        m = self.memory
        step = t - m["time"]
        now_in = delta > 0.0
        if now_in and not m["in_contact"] and step > 0.0:
            path = _EccentricityStep(
                m["eccentricity"], m["eccentricity_rate"], e, e_dot, step, self.clearance
            )
            m["impact_velocity"] = max(path.rate(path.crossing(0.0)), 0.0)
            self.contact_history.append((t, m["impact_velocity"]))
        elif not now_in:
            m["impact_velocity"] = 0.0
        m["in_contact"] = now_in
        m["penetration"], m["penetration_rate"], m["time"] = delta, rate, t
        m["eccentricity"], m["eccentricity_rate"] = e, e_dot
        self._memory_changed()
        return True

    # --- solving ---------------------------------------------------------------------------

    def settings(self, h, t_end, output_period=None):
        """Exudyn `SimulationSettings`: generalized-α, fixed step h, no files written, sensors
        stored in memory every `output_period` (None: no sensor output)."""
        ss = self.exu.SimulationSettings()
        n_steps = t_end / h
        if abs(n_steps - round(n_steps)) > 1e-6 * n_steps:
            raise ValueError(f"h = {h!r} s is invalid: it must divide t_end = {t_end!r} s")
        ti = ss.timeIntegration
        ti.numberOfSteps = int(round(n_steps))
        ti.endTime = t_end
        ti.generalizedAlpha.spectralRadius = self.rho_inf
        ti.adaptiveStep = False
        ti.verboseMode = 0
        ss.solution.file.write = False
        ss.solution.sensors.active = output_period is not None
        if output_period is not None:
            ss.solution.sensors.writePeriod = output_period
        ss.show.computationTime = False
        ss.show.statistics = False
        return ss

    def solve(self, h, t_end, ts=None) -> ExudynRun:
        """Generalized-α with fixed step h from t = 0 to `t_end`; states at `ts` (equally
        spaced from 0, with a spacing that h divides; None: no output)."""
        exu = self.exu
        period = None
        if ts is not None:
            ts = np.asarray(ts, dtype=float)
            period = float(ts[1] - ts[0]) if ts.size > 1 else t_end
            ratio = period / h
            if abs(ratio - round(ratio)) > 1e-6 * ratio or not np.allclose(
                np.diff(ts), period, rtol=1e-9, atol=0.0
            ):
                raise ValueError(
                    f"ts must be equally spaced with a spacing that h = {h!r} s divides "
                    f"(spacing {period!r} s)"
                )
        ss = self.settings(h, t_end, period)
        self._reset_memory()
        ok, message = True, "ok"
        start = time.perf_counter()
        try:
            with _quiet():
                ok = bool(exu.SolveDynamic(self.mbs, ss))
        except Exception as err:  # Exudyn raises SolverError when Newton fails for good
            ok, message = False, f"Exudyn failed: {err}"
        wall = time.perf_counter() - start
        solver = self.mbs.sys["dynamicSolver"]
        stats = solver.it
        failed_at = stats.currentTime
        if ok and not np.isclose(failed_at, t_end, rtol=1e-9, atol=1e-15):
            ok, message = False, f"Exudyn stopped at t = {failed_at:.6g} s"
        elif not ok and message == "ok":
            message = f"Exudyn failed at t = {failed_at:.6g} s"
        q = v = np.empty((0, 9))
        if ts is not None:
            q, v = self._sampled(ts)
        steps = int(stats.currentStepIndex) - 1
        return ExudynRun(
            q=q,
            v=v,
            steps=steps,
            rejected=0,
            newton_iterations=int(stats.newtonStepsCount),
            jacobians=int(stats.newtonJacobiCount),
            wall=wall,
            ok=ok,
            message=message,
        )

    def _sampled(self, ts):
        """Sensor rows at `ts` (matched by time; rows that Exudyn did not write are NaN)."""
        out = np.full((2, ts.size, 9), np.nan)
        tol = 1e-9 * max(float(ts[-1]), 1e-300)
        for k, sensor in enumerate(self.sensors):
            data = np.atleast_2d(self.mbs.GetSensorStoredData(sensor))
            if data.size == 0:
                continue
            idx = np.searchsorted(data[:, 0], ts - tol)
            idx = np.clip(idx, 0, data.shape[0] - 1)
            hit = np.abs(data[idx, 0] - ts) <= tol
            kind, node = divmod(k, 3)
            out[kind, hit, 3 * node : 3 * node + 3] = data[idx[hit], 1:4]
        return out[0], out[1]


class _quiet:
    """Silence Exudyn's C++ console output (it prints solver messages on stdout)."""

    def __enter__(self):
        sys.stdout.flush()
        self._saved = os.dup(1)
        self._null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(self._null, 1)

    def __exit__(self, *exc):
        sys.stdout.flush()
        os.dup2(self._saved, 1)
        os.close(self._saved)
        os.close(self._null)
        return False
