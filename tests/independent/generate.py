"""Write `tests/data/slider_crank_reference.npz`: the minimal-coordinate slider-crank reference
(`slider_crank_minimal.py`) for μ = 0 and μ = 0.01, with its convergence evidence.

Run from the repository root:

    cd tests && python -m independent.generate            # ~3 min on one core

For each case the file holds (prefix `mu0_` or `mu0.01_`):

* `onsets`, `separations` [s], `impact_velocities` [m/s] over two revolutions;
* `fine`: (φ [rad], x_s [m]) at `fine_ts` = 0, 1 µs, …, 4 ms;
* `coarse`: x_s [m] at `coarse_ts` = every 10 µs over two revolutions;

and `meta`, a JSON string: parameters, integrator settings, library versions, and for each
check run (DOP853 at 10× the tolerance, Radau) its largest differences to the stored run —
onset times, x_s over the first 4 ms, x_s over two revolutions — which bound the stored run's
error (Hairer, Nørsett & Wanner, *Solving ODEs I*, §II.4: a tight run's error estimated by a
looser one's difference).
"""

from __future__ import annotations

import json
import os
import sys

import numpy as np
import scipy

from .slider_crank_minimal import TWO_REVOLUTIONS, SliderCrankMinimal

PATH = os.path.join(os.path.dirname(__file__), os.pardir, "data", "slider_crank_reference.npz")
FINE_TS = np.linspace(0.0, 4e-3, 4001)
COARSE_TS = np.linspace(0.0, TWO_REVOLUTIONS, 2401)

# DOP853 settings of the stored runs; atol per (φ [rad], x_s [m], φ̇ [rad/s], ẋ_s [m/s]).
# With friction the run is more sensitive (43 impacts instead of 26), so it is integrated
# at scipy's smallest accepted rtol (100 ε).
CASES = {
    "mu0": dict(
        params={"friction_coefficient": 0.0},
        rtol=1e-13,
        atol=(1e-15, 1e-16, 1e-12, 1e-13),
        checks=(("DOP853", 1e-12), ("Radau", 1e-11)),
    ),
    "mu0.01": dict(
        params={"friction_coefficient": 0.01, "friction_slip_velocity": 1e-3},
        rtol=2.5e-14,
        atol=(1e-16, 1e-17, 1e-13, 1e-14),
        checks=(("DOP853", 2.5e-13), ("Radau", 1e-12)),
    ),
}


def run_case(case, rtol=None, method="DOP853"):
    spec = CASES[case]
    model = SliderCrankMinimal(spec["params"])
    tol = spec["rtol"] if rtol is None else rtol
    atol = np.asarray(spec["atol"]) * tol / spec["rtol"]
    return model, model.solve(TWO_REVOLUTIONS, rtol=tol, atol=atol, method=method)


def arrays(solution):
    fine = solution.sample(FINE_TS)[:, :2]
    return {
        "onsets": np.array(solution.onsets),
        "separations": np.array(solution.separations),
        "impact_velocities": np.array(solution.impact_velocities),
        "fine": fine,
        "coarse": solution.sample(COARSE_TS)[:, 1],
    }


def differences(a, b):
    """Largest differences between two runs' arrays (None for the onsets if the counts
    differ)."""
    same = a["onsets"].size == b["onsets"].size
    return {
        "n_onsets": [int(a["onsets"].size), int(b["onsets"].size)],
        "onsets_s": float(np.max(np.abs(a["onsets"] - b["onsets"]))) if same else None,
        "x_s_4ms_m": float(np.max(np.abs(a["fine"][:, 1] - b["fine"][:, 1]))),
        "x_s_two_revolutions_m": float(np.max(np.abs(a["coarse"] - b["coarse"]))),
    }


def main():
    out = {"fine_ts": FINE_TS, "coarse_ts": COARSE_TS}
    meta = {
        "command": "cd tests && python -m independent.generate",
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "python": sys.version.split()[0],
        "t_end_s": TWO_REVOLUTIONS,
        "cases": {},
    }
    for case, spec in CASES.items():
        model, stored = run_case(case)
        stored_arrays = arrays(stored)
        checks = []
        for method, tol in spec["checks"]:
            _, check = run_case(case, tol, method)
            checks.append(
                {"method": method, "rtol": tol, **differences(arrays(check), stored_arrays)}
            )
            print(case, checks[-1], flush=True)
        meta["cases"][case] = {
            "params": model.p,
            "stiffness_N_per_m1.5": model.K,
            "method": "DOP853",
            "rtol": spec["rtol"],
            "atol": list(spec["atol"]),
            "n_steps": stored.n_steps,
            "n_tensile_events": stored.n_tensile_events,
            "n_grazing_recoveries": stored.n_grazing_recoveries,
            "checks": checks,
        }
        out.update({f"{case}_{k}": v for k, v in stored_arrays.items()})
    out["meta"] = np.array(json.dumps(meta, indent=1))
    os.makedirs(os.path.dirname(PATH), exist_ok=True)
    np.savez_compressed(PATH, **out)
    print(f"wrote {os.path.normpath(PATH)} ({os.path.getsize(PATH) / 1024:.0f} KiB)")


if __name__ == "__main__":
    main()
