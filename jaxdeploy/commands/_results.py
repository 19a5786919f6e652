"""What the keys of `summary.json` mean: each key (or key pattern) with its unit and a one-line
description. `jaxdeploy simulate` writes the units of a run's quantities as the summary's
`units` map; docs/results.md shows the descriptions (tests/test_results_keys.py checks that
every key a scene writes is here and on that page, so a new summary quantity cannot go out
undocumented).

Units: SI; "-" for a dimensionless number or a count; "" for text and records.
"""

from __future__ import annotations

import re

PANEL = r"panel\d+"
# (key or regular expression matching the whole key, unit, description)
SUMMARY_KEYS = (
    ("scene", "", "the scene's name"),
    ("t_end_s", "s", "end time of the run"),
    (
        "status",
        "",
        '"ok"; "failed after t = ...: why" when the solver stopped; "implausible: ..." naming '
        "each failed plausibility check and its value",
    ),
    ("t_reached_s", "s", "time the integration reached (t_end unless it failed)"),
    ("n_steps", "-", "accepted steps"),
    ("n_rejected", "-", "rejected steps (adaptive step control)"),
    ("n_newton_iterations", "-", "Newton iterations (generalized-α; null on the ODE path)"),
    ("wall_time_s", "s", "wall time of the whole command"),
    (
        "phases",
        "s",
        "wall time of each phase: build_s (mechanism, initial state; read back from the "
        "scene cache when an earlier run built the same scene and parameters), compile_s (of the "
        "run; after a fresh build, what the run still waits for of its program compiled "
        "ahead), compile_ahead_s (that compile: the run's program traced and compiled in a "
        "second thread while the initial state is assembled, overlapping build_s, whose "
        "assembly begins once that program is traced), "
        "integrate_s, reference_compile_s and reference_s (the ideal-joint reference "
        "run, deploy_array without --no-reference, made in a second thread beside the run: "
        "they overlap compile_s and integrate_s), reference_wait_s (waiting for it after the "
        "run), outputs_s (summary quantities, trajectory.npz; the figures are drawn meanwhile "
        "in a second process), plots_s (waiting for the figures after that)",
    ),
    ("params", "", "every scene parameter of the run, SI units (`jaxdeploy scenes SCENE`)"),
    ("scene_options", "", "the scene's options (constructor keywords)"),
    ("seed", "", "random seed (null: the command draws no random numbers)"),
    ("step_control", "", "solver and step control (`StepControl.to_json`)"),
    ("versions", "", "package versions, platform, devices, git commit of the code"),
    ("units", "", "the unit of every quantity in the summary"),
    # pendulum
    ("max_constraint_violation", "m", "largest absolute constraint residual Φ(q), saved states"),
    # slider_crank
    ("slider_acc_min", "m/s²", "smallest slider acceleration (every accepted step)"),
    ("slider_acc_max", "m/s²", "largest slider acceleration (every accepted step)"),
    # clearance joints (slider_crank, deploy_array)
    # Extremes tracked over every accepted step (not the saved states): docs/output_extremes.md
    ("max_contact_force", "N", "largest normal contact force of any clearance joint"),
    ("max_penetration", "m", "largest penetration of any clearance joint"),
    (rf"{PANEL}_max_contact_force", "N", "largest normal contact force of the panel's hinge"),
    (rf"{PANEL}_max_penetration", "m", "largest penetration of the panel's hinge"),
    # deploy_array
    ("lock_time", "s", "time the latch engages (null: not within t_end)"),
    ("lock_time_ideal", "s", "lock time of the ideal-joint mechanism"),
    (
        "max_angle_deviation_deploy",
        "rad",
        "largest absolute deviation α − α_ideal of the deployment angle up to the lock",
    ),
    ("max_angle_deviation_locked", "rad", "largest absolute deviation α − α_ideal after the lock"),
    (rf"{PANEL}_max_dx", "m", "largest x deviation of the panel's centre from the ideal run"),
    (rf"{PANEL}_max_dy", "m", "largest y deviation of the panel's centre from the ideal run"),
    (rf"{PANEL}_tip_max_dx", "m", "largest x deviation of the panel's tip from the ideal run"),
    (rf"{PANEL}_tip_max_dy", "m", "largest y deviation of the panel's tip from the ideal run"),
    (
        rf"{PANEL}_peak_freq_hz",
        "Hz",
        "frequency of the largest peak of the panel's post-lock acceleration spectrum",
    ),
    ("ideal_reference_status", "", "status of the ideal-joint reference run"),
    (
        "energy_balance",
        "-",
        "a sweep case's energy-balance residual over the energy moved (the plausibility check "
        "energy_balance, limit 3e-3; null where the mechanism cannot be metered, e.g. with a "
        "driver, and for a failed case)",
    ),
    (
        "plausibility",
        "",
        "each plausibility check of the run (check, value, limit, unit, subject, passed; value "
        "and passed null for a check the run cannot make, e.g. the energy balance with a "
        "driver); docs/robustness.md",
    ),
)


def run_quantities(trajectory) -> dict:
    """The quantities every run reports, whatever its scene: status, time reached, steps."""
    return {
        "status": trajectory.status(),
        # Where the integration stopped: t_end, or the failure's time (not the last save).
        "t_reached_s": trajectory.time_reached(),
        "n_steps": int(trajectory.stats["num_accepted_steps"]),
        "n_rejected": int(trajectory.stats["num_rejected_steps"]),
        # Newton iterations exist only for generalized-α; null for the explicit diffrax path.
        "n_newton_iterations": (
            int(trajectory.stats["num_newton_iterations"])
            if "num_newton_iterations" in trajectory.stats
            else None
        ),
    }


def failed_run_summary(quantities: dict) -> dict:
    """The scene's summary `quantities` of a failed run: every value null (its states past
    the failure are NaN, its extremes may be those of a diverging force), the keys kept so
    that every run's summary has the same fields."""
    return {key: None for key in quantities}


def describe_key(key: str) -> tuple[str, str] | None:
    """`(unit, description)` of summary key `key`, or None if it is not documented."""
    for pattern, unit, description in SUMMARY_KEYS:
        if re.fullmatch(pattern, key):
            return unit, description
    return None


def units_of(summary: dict) -> dict[str, str]:
    """`{key: unit}` for the quantities (numbers, and maps of numbers such as `phases`) of
    `summary`; an undocumented key gets "?" (tests catch it)."""
    units = {}
    for key, value in summary.items():
        if isinstance(value, bool) or not isinstance(value, int | float | dict | type(None)):
            continue
        if key in ("params", "scene_options", "step_control", "versions", "seed", "units"):
            continue
        found = describe_key(key)
        units[key] = "?" if found is None else found[0]
    return units
