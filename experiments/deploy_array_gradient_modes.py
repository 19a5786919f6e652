"""deploy_array's derivatives over its first hinge impacts at fixed steps: forward mode against
reverse mode, and both against central differences over a sweep of steps.

This was the slow test `test_deploy_array_reverse_and_forward_match_central_differences`
(tests/test_gradients.py; 0–30 ms, fixed Tsit5 steps of 20 µs, tip acceleration and
deployment angle w.r.t. Ra, c of both hinges, c_e, μ and E). It asserted reverse mode within
1e-4 of the largest difference at one relative step (1e-5) and forward mode within 1e-9 of
reverse mode, and had been an expected failure since the continuous v⁻ rule and modified
Newton (up to 130 % off on panel1_ra): the map is linear over too small a parameter range for
one step to be the derivative (docs/identification.md, "Replayed derivatives over the
horizon"), and the two modes round differently on an ill-conditioned derivative (the slider-crank
revolution's conditioning, tests/test_gradients.py). As an expected failure it cost ~14 min of
every full test run and asserted nothing; what it measured is a number to look at, so it is
this script. The gradient machinery itself is checked where a comparison means something:
tests/test_gradients.py (impact and slider-crank, fixed and replayed adaptive steps) and
tests/test_event_gradients.py (deploy_array's lock time against rerun differences).

For each horizon the script prints, per parameter, max |forward − reverse| and
max |FD_h − forward| for each relative step h, both relative to the largest |forward| entry.
The differences' runs are the primal outputs of the forward-mode program at θ ± h (the same
fixed steps, one compilation).

Usage: `PYTHONPATH=. python experiments/deploy_array_gradient_modes.py [--t-end 0.01 0.03]
[--json PATH]`.
"""

from __future__ import annotations

import argparse
import json
import time

import jax
import jax.numpy as jnp
import numpy as np

from jaxdeploy.fit import output_function
from jaxdeploy.io import run_metadata
from jaxdeploy.scenes import DeployArray

PARAMS = ["panel1_ra", "panel1_clearance", "panel2_clearance", "restitution",
          "friction_coefficient", "youngs_modulus"]  # fmt: skip
STEPS = [1e-4, 1e-5, 1e-6, 1e-7]
CONTROL = {"rtol": None, "atol": None, "dt_max": None, "dt": 2e-5}


def output(ch):
    """Tip acceleration and deployment angle (mrad) at the saved times past the first third."""
    return jnp.concatenate([ch["panel2_tip_ay"][5:], 1e3 * ch["alpha"][5:]])


def measure(t_end: float) -> dict:
    scene = DeployArray()
    base = scene.resolve_params()
    ts = jnp.linspace(0.0, t_end, 16)
    programs = {}
    for mode, transform in (("forward", jax.jacfwd), ("reverse", jax.jacrev)):
        f, x0 = output_function(scene, base, PARAMS, output, t_end, mode=mode, ts=ts,
                                control=CONTROL)  # fmt: skip

        def value_twice(x, f=f):
            y = f(x)
            return y, y

        programs[mode] = jax.jit(transform(value_twice, has_aux=True))
    start = time.process_time()
    fwd, _ = programs["forward"](x0)
    rev, _ = programs["reverse"](x0)
    row = {"t_end": t_end, "params": {}}
    for name in PARAMS:
        a, r = np.asarray(fwd[name]), np.asarray(rev[name])
        scale = float(np.abs(a).max())
        entry = {"max_abs_forward": scale, "forward_vs_reverse": float(np.abs(a - r).max()) / scale}
        entry["fd_vs_forward"] = {}
        for h in STEPS:
            step = h * abs(x0[name])
            _, plus = programs["forward"]({**x0, name: x0[name] + step})
            _, minus = programs["forward"]({**x0, name: x0[name] - step})
            d = (np.asarray(plus) - np.asarray(minus)) / (2 * step)
            entry["fd_vs_forward"][f"{h:g}"] = float(np.abs(d - a).max()) / scale
        row["params"][name] = entry
    row["cpu_s"] = time.process_time() - start
    return row


def main(argv=None):
    parser = argparse.ArgumentParser()
    parser.add_argument("--t-end", type=float, nargs="+", default=[0.01, 0.03])
    parser.add_argument("--json", help="also write the rows to this file")
    args = parser.parse_args(argv)
    rows = []
    for t_end in args.t_end:
        row = measure(t_end)
        rows.append(row)
        print(f"0–{t_end:g} s, fixed steps of {CONTROL['dt']:g} s ({row['cpu_s']:.0f} CPU-s):")
        print("  parameter            |fwd−rev|   " + "  ".join(f"FD h={h:<6g}" for h in STEPS))
        for name, e in row["params"].items():
            fd = "  ".join(f"{e['fd_vs_forward'][f'{h:g}']:<11.2g}" for h in STEPS)
            print(f"  {name:20s} {e['forward_vs_reverse']:<11.2g} {fd}")
    if args.json:
        with open(args.json, "w") as out:
            json.dump({"rows": rows, "versions": run_metadata()}, out, indent=1)


if __name__ == "__main__":
    main()
