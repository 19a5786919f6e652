"""Write the slider-crank "measurements" in `examples/`: the Flores & Ambrósio (2004)
slider-crank computed by a model that shares no code with jaxdeploy, plus stated noise.

The slider position x_s [m] of the independent minimal-coordinate reference
(`tests/independent/slider_crank_minimal.py`: classical Lankarani–Nikravesh rule, c = 0.5 mm,
c_e = 0.9), plus white Gaussian noise of σ = 1 µm (seed 2026), which each file states on its
`# sigma_slider_x` line:

* `slider_crank_slider_x.csv`: μ = 0, 0–4 ms every 20 µs (the README's worked example), from
  a DOP853 run at rtol 1e-12 with every contact onset and separation located;
* `slider_crank_slider_x_12ms.csv`: μ = 0, 0–12 ms every 20 µs (the case of issue 20);
* `slider_crank_friction_slider_x_12ms.csv`: μ = 0.01 with the reference's tanh-regularised
  Coulomb law (slip velocity 1 mm/s), 0–12 ms every 20 µs.

The two 12 ms files sample the stored reference runs `tests/data/slider_crank_reference.npz`
(DOP853 at rtol 1e-13 and 2.5e-14; their recorded convergence checks bound the error of x_s
by 2e-9 m, far below σ) every second sample. Run from the repository root:

    python experiments/slider_crank_measurements.py
"""

import json
import os
import sys

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), os.pardir)
sys.path.insert(0, os.path.join(ROOT, "tests"))

from independent.slider_crank_minimal import SliderCrankMinimal  # noqa: E402

EXAMPLES = os.path.join(ROOT, "examples")
REFERENCE = os.path.join(ROOT, "tests", "data", "slider_crank_reference.npz")
SIGMA = 1e-6  # [m]
SEED = 2026


def write(name, ts, x, header):
    noisy = x + SIGMA * np.random.default_rng(SEED).standard_normal(ts.size)
    lines = [
        *(f"# {line}" for line in header),
        "# plus white noise; made by experiments/slider_crank_measurements.py",
        f"# sigma_slider_x = {SIGMA!r}",
        "t,slider_x",
        *(f"{t:.6g},{y:.12g}" for t, y in zip(ts, noisy, strict=True)),
    ]
    path = os.path.join(EXAMPLES, name)
    os.makedirs(EXAMPLES, exist_ok=True)
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("\n".join(lines) + "\n")
    print(f"wrote {os.path.normpath(path)}: {ts.size} samples")


def main():
    ts = np.linspace(0.0, 4e-3, 201)  # [s]
    solution = SliderCrankMinimal({"clearance": 0.5e-3, "restitution": 0.9}).solve(
        float(ts[-1]), rtol=1e-12
    )
    header = [
        "slider position of the Flores & Ambrosio (2004) slider-crank, c = 0.5 mm, c_e = 0.9,",
        "from tests/independent/slider_crank_minimal.py (classical Lankarani-Nikravesh rule)",
    ]
    write("slider_crank_slider_x.csv", ts, solution.sample(ts)[:, 1], header)

    stored = np.load(REFERENCE)
    meta = json.loads(str(stored["meta"]))
    keep = stored["coarse_ts"] <= 12e-3 + 1e-12
    ts = stored["coarse_ts"][keep][::2]
    for case, name in (("mu0", "slider_crank_slider_x_12ms.csv"),
                       ("mu0.01", "slider_crank_friction_slider_x_12ms.csv")):  # fmt: skip
        p = meta["cases"][case]["params"]
        header = [
            "slider position of the Flores & Ambrosio (2004) slider-crank, "
            f"c = {p['clearance'] * 1e3:g} mm, c_e = {p['restitution']:g}, "
            f"mu = {p['friction_coefficient']:g}"
            + (
                f" (tanh law, slip velocity {p['friction_slip_velocity']:g} m/s),"
                if p["friction_coefficient"]
                else ","
            ),  # fmt: skip
            f"tests/data/slider_crank_reference.npz ({case}; tests/independent/, classical "
            "Lankarani-Nikravesh rule)",
        ]
        write(name, ts, stored[f"{case}_coarse"][keep][::2], header)


if __name__ == "__main__":
    main()
