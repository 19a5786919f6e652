"""The lock time's derivatives checked from Python: `fit.gradient_check` on deploy_array's
lock time in the spring stiffness, the root hinge's clearance and the restitution, at the
scene's defaults (the same check as `jaxdeploy gradcheck deploy_array --output lock_time
--params spring_stiffness panel1_clearance restitution`). Writes the block `gradcheck_lock_time`
of docs/identification.md and docs/figures/gradcheck_lock_time.png.

    python experiments/gradcheck_lock_time.py     # ~10-30 CPU-min on a 2-core machine
"""

from __future__ import annotations

import os
import sys

import jaxdeploy
from jaxdeploy import pages
from jaxdeploy.fit import gradient_check
from jaxdeploy.scenes import get_scene

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PARAMS = ("spring_stiffness", "panel1_clearance", "restitution")
# What moves the numbers: deploy_array's runs, their derivatives and the check itself.
MEASURES = [
    "jaxdeploy/batch.py",
    "jaxdeploy/contact",
    "jaxdeploy/fit/_derivatives.py",
    "jaxdeploy/fit/_derivative_tolerance.py",
    "jaxdeploy/fit/_gradcheck.py",
    "jaxdeploy/mechanism",
    "jaxdeploy/scenes/_contact.py",
    "jaxdeploy/scenes/base.py",
    "jaxdeploy/scenes/data",
    "jaxdeploy/scenes/deploy_array.py",
    "jaxdeploy/simulation.py",
    "jaxdeploy/solvers",
    "experiments/gradcheck_lock_time.py",
]


def _table(check) -> list[str]:
    lines = [
        "| parameter | value | AD forward | AD reverse | converged FD (kind, spread) | "
        "relative error | agreeing steps (replayed; rerun) | failed runs | agree |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, p in check.params.items():
        spans = []
        for kind in ("replay", "rerun"):
            steps = p.agreeing_steps(kind)
            spans.append(f"{steps[0]}…{steps[-1]}" if steps else "none")
        failed = "; ".join(f"{kind} {', '.join(s)}" for kind, s in p.failed.items()) or "none"
        lines.append(
            f"| `{name}` | {p.value:.6g} | {p.ad:.8g} | {p.ad_reverse:.8g} | {p.converged:.8g} "
            f"({p.converged_kind}, {p.spread:.1e}) | {p.relative_error:.1e} | "
            f"{spans[0]}; {spans[1]} | {failed} | {'yes' if p.agree else 'NO'} |"
        )
    return lines


def main() -> int:
    record = pages.start(MEASURES, "python experiments/gradcheck_lock_time.py")
    jaxdeploy.enable_caches()
    scene = get_scene("deploy_array")
    params = scene.resolve_params({})
    # The horizon the command picks without --t-end: 5 % past the event (lock ≈ 0.54 s).
    check = gradient_check(
        scene, params, PARAMS, "lock_time", 0.57,
        progress=lambda message: print(message, file=sys.stderr, flush=True),
    )  # fmt: skip
    figure = "figures/gradcheck_lock_time.png"
    check.plot(os.path.join(ROOT, "docs", figure))
    lines = [
        f'`fit.gradient_check(scene, params, {list(PARAMS)}, "lock_time", 0.57)` on '
        f"deploy_array at the scene's defaults: lock time {check.value:.10g} s; "
        f"{check.step_tolerance.summary()}; relative steps "
        + ", ".join(f"{h:g}" for h in check.steps)
        + f", tolerance {check.tolerance:g}. Verdict: **{check.verdict}**.",
        "",
        *_table(check),
        "",
        f"![|FD − AD|/|AD| against the step]({figure})",
    ]
    pages.write_block(
        os.path.join(ROOT, "docs/identification.md"), "gradcheck_lock_time", "\n".join(lines),
        record,
    )  # fmt: skip
    print(check.table())
    return 0 if check.verdict == "agree" else 1


if __name__ == "__main__":
    sys.exit(main())
