"""Whether a run that the solver finished is physically plausible: the checks every
`jaxdeploy simulate` and every sweep case passes before its status may read "ok".

A solver that finishes has only kept its own error estimate within the tolerances; with
tolerances too loose for the scene, or parameters outside the contact law's range, it can
finish with a journal sunk a metre into its bearing. Each check compares one quantity of the
run with a limit the physics sets:

* **penetration per clearance**: the largest penetration δ of each clearance joint against
  its radial clearance c. The contact laws (`jaxdeploy.contact`) are point-contact laws: the
  journal touches the bearing along a narrow arc. The journal overlaps the bearing where
  e·cos φ > c, with e = c + δ, i.e. over the half-angle φ = arccos(c / (c + δ)): 60° at
  δ = c, 70.5° at δ = 2c. For internal cylinders the effective radius is R* ≈ R_j²/c, and
  with δ ≈ a²/R* the contact half-width is a ≈ R_j·sqrt(δ/c): Hertz's assumption a ≪ R_j
  (Johnson 1985, Contact Mechanics, §4.1) already fails near δ ≈ c. The limit
  δ ≤ `PENETRATION_PER_CLEARANCE` · c is a generous one that flags runs clearly past it (the
  impact scene's default, a 1-D closed-form check with a given stiffness, reaches δ = 1.05 c).
* **penetration per journal radius**: δ against the journal radius R_j. Hertz theory assumes
  small strains, a contact zone small against the radii of the bodies (Johnson 1985,
  Contact Mechanics, §4.1). Limit: δ ≤ `PENETRATION_PER_RADIUS` · R_j.
* **constraint drift**: the largest |Φ(q)| of the ideal joints at the saved states. A drift
  comparable to a clearance moves the joints as much as the clearance the run studies. Limit:
  `DRIFT_PER_CLEARANCE` of the smallest clearance; in a mechanism without clearance joints
  `DRIFT_LIMIT_M`.
* **energy balance** (`energy_check`, runs metered by `mechanism.balance_metered`): the
  largest |T + V + D − T(0) − V(0) − J| over the saved states against the energy moved
  (`mechanism.energy_moved`); the work–energy theorem (Géradin & Cardona 2001, §6) holds for
  the model exactly, so the residual is the integrator's error and numerical dissipation plus
  the meter's trapezoid quadrature. Limit `ENERGY_RESIDUAL` = 3e-3, measured (CPU runs at
  the scenes' default step control unless said): the default runs leave 9e-6 (pendulum),
  4e-6 (impact), 3.4e-4 (deploy_array to 0.7 s and to 2 s), the robustness matrix's
  default-tolerance deploy_array cases at most 1.2e-3 (μ = 0; docs/robustness.md): 2.5× below
  the limit. Runs that are wrong leave more: deploy_array at rtol 1e-3 or 1e-2 (atol 5e-7)
  6.1e-3 and 6.0e-3 (its largest penetration moved by 19 % and 25 %), the pendulum with fixed
  steps of 0.05 s 2.3e-2, the impact resolved by 2, 4, 8 fixed steps 0.33, 0.12, 3.8e-2. Not
  computed (null) for a mechanism with a driver (slider_crank's crank) or with elements
  whose internal states the meter cannot meter (LuGre friction).
* **step per contact** (fixed-step runs): the step against the shortest contact episode that
  ended in the run. Generalized-α is second order: on the impact's Hertz contact (3.2e-4 s)
  the largest penetration is off by 15 %, 4.5 %, 1.5 %, 0.94 %, 0.25 % with 2, 4, 8, 10, 20
  steps per contact. Limit `STEP_PER_CONTACT` = 0.1 (at least 10 steps: the peak within
  ~1 %). Adaptive runs resolve a contact by their error control, whose absolute tolerance is
  checked against the clearance before the run (`tolerance_problem`); a run that needs more
  steps than `max_steps` is refused before it starts when t_end/dt_max shows it, else it
  fails with the solver's status.

The limits are this package's rules (the literature gives ranges of validity, not sharp
limits); docs/robustness.md lists them with their reasons.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

PENETRATION_PER_CLEARANCE = 2.0  # contact half-arc 70.5°, a ≈ 1.4 R_j
PENETRATION_PER_RADIUS = 0.1
DRIFT_PER_CLEARANCE = 0.01
DRIFT_LIMIT_M = 1e-6
# A fixed step may last this part of the shortest contact episode (module docstring).
STEP_PER_CONTACT = 0.1
# The energy balance's residual may reach this part of the energy moved (module docstring:
# 2.5x the largest residual measured at default tolerances, half that of a run at rtol 1e-3).
ENERGY_RESIDUAL = 3e-3
# An absolute step tolerance above this part of the smallest clearance is refused up front.
ATOL_PER_CLEARANCE = 0.01


@dataclass(frozen=True)
class Check:
    """One plausibility check of a run: its `name`, the `value` measured, the `limit` it may
    reach, its `unit`, and what was compared (`subject`)."""

    name: str
    value: float
    limit: float
    unit: str
    subject: str

    @property
    def passed(self) -> bool | None:
        # NaN fails: a quantity the run could not compute is no evidence of plausibility.
        # None: a check this run cannot make (e.g. no energy balance with a driver).
        if self.value is None:
            return None
        return bool(self.value <= self.limit)

    def message(self) -> str:
        unit = "" if self.unit == "-" else f" {self.unit}"
        return (
            f"{self.name} = {self.value:.3g}{unit} exceeds its limit {self.limit:.3g}{unit} "
            f"({self.subject})"
        )

    def to_json(self) -> dict:
        return {
            "value": self.value,
            "limit": self.limit,
            "unit": self.unit,
            "subject": self.subject,
            "passed": self.passed,
        }


def clearance_joints(mechanism) -> list[tuple[int, object]]:
    """`(element index, RevoluteClearance)` of every clearance joint of `mechanism`."""
    from ..mechanism import RevoluteClearance

    return [(i, mechanism.elements[i]) for i in mechanism.find(RevoluteClearance)]


def smallest_clearance(mechanism) -> float | None:
    """The smallest radial clearance [m] of `mechanism`'s clearance joints, or None."""
    joints = clearance_joints(mechanism)
    return min(float(j.clearance) for _, j in joints) if joints else None


def _penetration_checks(mechanism, trajectory) -> list[Check]:
    from .contact_forces import contact_extremes

    extremes = contact_extremes(mechanism, trajectory)
    checks = []
    for index, joint in clearance_joints(mechanism):
        delta = extremes[index]["max_penetration"]
        c, radius = float(joint.clearance), float(joint.journal_radius)
        where = f"clearance joint {index} ({joint.bearing_body}/{joint.journal_body})"
        checks.append(
            Check(
                "penetration_per_clearance",
                delta / c,
                PENETRATION_PER_CLEARANCE,
                "-",
                f"{where}: largest penetration {delta:.3g} m in a clearance of {c:.3g} m",
            )
        )
        checks.append(
            Check(
                "penetration_per_radius",
                delta / radius,
                PENETRATION_PER_RADIUS,
                "-",
                f"{where}: largest penetration {delta:.3g} m, journal radius {radius:.3g} m",
            )
        )
    return checks


def _drift_check(mechanism, trajectory) -> list[Check]:
    if not mechanism.n_constraints:
        return []
    residual = np.asarray(_residuals(_traced_numbers(mechanism), trajectory.q, trajectory.ts))
    drift = float(np.max(np.abs(residual))) if residual.size else 0.0
    c = smallest_clearance(mechanism)
    if c is None:
        limit, subject = DRIFT_LIMIT_M, "largest |Φ(q)| of the saved states"
    else:
        limit = DRIFT_PER_CLEARANCE * c
        subject = f"largest |Φ(q)| of the saved states, smallest clearance {c:.3g} m"
    return [Check("constraint_drift", drift, limit, "m", subject)]


def _traced_numbers(mechanism):
    """`mechanism` with its Python numbers (parameters) as arrays: `_residuals` then compiles
    once per mechanism structure, not once per parameter set (a sweep's cases)."""
    import jax
    import jax.numpy as jnp

    def as_array(leaf):
        if isinstance(leaf, int | float) and not isinstance(leaf, bool):
            return jnp.asarray(leaf, dtype=float)
        return leaf

    return jax.tree.map(as_array, mechanism)


@functools.cache
def _residual_program():
    import equinox as eqx
    import jax

    @eqx.filter_jit
    def residuals(mechanism, q, ts):
        return jax.vmap(mechanism.constraints)(q, ts)

    return residuals


def _residuals(mechanism, q, ts):
    """Φ(q, t) of every saved state (one compiled program per mechanism structure), through
    the program cache when it is on: a warm `jaxdeploy simulate` reads the program back
    instead of tracing it (`jaxdeploy/_program_cache.py`)."""
    from .. import _program_cache

    return _program_cache.call(_residual_program(), mechanism, q, ts)


def _contact_steps_check(mechanism, trajectory) -> list[Check]:
    """Fixed-step runs: the step against the shortest contact episode that ended within the
    run (module docstring). Adaptive runs resolve a contact by their error control (whose
    tolerances `tolerance_problem` checks before the run): no check."""
    control = trajectory.control
    if control is None or control.adaptive or not is_number(control.dt):
        return []
    shortest, where = math.inf, None
    joints = clearance_joints(mechanism)
    for (index, joint), episodes in zip(joints, trajectory.contact_episodes(), strict=False):
        durations = np.asarray(episodes.separation_time) - np.asarray(episodes.onset_time)
        durations = durations[np.isfinite(durations)]
        if durations.size and durations.min() < shortest:
            shortest = float(durations.min())
            where = f"clearance joint {index} ({joint.bearing_body}/{joint.journal_body})"
    if where is None:
        return []
    dt = float(control.dt)
    return [
        Check(
            "step_per_contact",
            dt / shortest,
            STEP_PER_CONTACT,
            "-",
            f"{where}: fixed step {dt:.3g} s, shortest contact episode {shortest:.3g} s "
            f"({shortest / dt:.3g} steps)",
        )
    ]


def is_number(value) -> bool:
    return isinstance(value, int | float) and math.isfinite(value)


def energy_check(balance: dict | None, unmetered: str | None = None) -> Check:
    """The energy balance of a run (`mechanism.metered_balance`): the largest
    |T + V + D − T(0) − V(0) − J| over the saved states against the energy moved
    (`mechanism.energy_moved`). `balance` None: not computed, `unmetered` says why (the
    check's value is then None, neither passed nor failed)."""
    subject = "largest |T + V + D − T(0) − V(0) − J| of the saved states / the energy moved"
    if balance is None:
        return Check("energy_balance", None, ENERGY_RESIDUAL, "-", f"not computed: {unmetered}")
    from ..mechanism import energy_moved

    moved = energy_moved(balance)
    residual = float(np.max(np.abs(np.asarray(balance["residual"]))))
    # A run in which nothing moved has no scale: judge its residual against its energy.
    level = np.asarray(balance["kinetic"]) + np.asarray(balance["potential"])
    scale = max(moved, 1e-9 * float(np.max(np.abs(level))), 1e-300)
    return Check(
        "energy_balance",
        residual / scale,
        ENERGY_RESIDUAL,
        "-",
        f"{subject}: residual {residual:.3g} J, energy moved {moved:.3g} J",
    )


def case_energy(mechanism, trajectory):
    """`(energy, trajectory)` of a run of `mechanism` that ran with its energy meter where
    the mechanism allows one (`mechanism.balance_metered`; a sweep's case,
    `batch.run_scene(..., energy_meter=True)`): `energy()` its `energy_check` (value None,
    saying why, when the mechanism cannot be metered), and the run as one of `mechanism`,
    without the meter's memory. The balance compiles once per mechanism structure, not per
    case (`_traced_numbers`)."""
    from ..mechanism import (
        balance_metered,
        metered_balance,
        unmetered_because,
        without_balance_meter,
    )

    metered = balance_metered(mechanism)
    memory = trajectory.memory
    if metered is None or memory is None or len(memory) != len(metered.elements):
        why = unmetered_because(mechanism) or "the run was not metered"
        return (lambda: energy_check(None, why)), trajectory

    def energy():
        balance = metered_balance(_traced_numbers(metered), trajectory.q, trajectory.v, memory)
        return energy_check(balance)

    return energy, without_balance_meter(trajectory)


def plausibility_checks(mechanism, trajectory, energy: Check | None = None) -> list[Check]:
    """Every plausibility check of a finished run (module docstring), passed or not;
    `energy` (`energy_check`) is added when given."""
    checks = _penetration_checks(mechanism, trajectory) + _drift_check(mechanism, trajectory)
    checks += _contact_steps_check(mechanism, trajectory)
    return checks + ([] if energy is None else [energy])


def verdict(trajectory, checks) -> str:
    """The run's status: the solver's own failure (`Trajectory.status`), else
    `"implausible: ..."` naming every failed check and its value, else `"ok"`."""
    if not trajectory.ok:
        return trajectory.status()
    failed = [c.message() for c in checks if c.passed is False]
    return "ok" if not failed else "implausible: " + "; ".join(failed)


def tolerance_problem(mechanism, control) -> str | None:
    """Why `control`'s tolerances are too loose to mean anything for `mechanism`, or None:
    an absolute tolerance above `ATOL_PER_CLEARANCE` of the smallest clearance lets each step
    err by that part of the gap the run resolves (positions are in m, and the error norm
    takes them with atol)."""
    c = smallest_clearance(mechanism)
    atol = getattr(control, "atol", None)
    if c is None or atol is None or not control.adaptive:
        return None
    if atol > ATOL_PER_CLEARANCE * c:
        return (
            f"--atol = {atol:g} is too loose for a clearance of {c:g} m: each step could err "
            f"by more than {ATOL_PER_CLEARANCE:g} of the gap it resolves; give --atol ≤ "
            f"{ATOL_PER_CLEARANCE * c:g}"
        )
    return None
