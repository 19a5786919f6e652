"""Write `examples/slider_crank_slider_x.csv`: "measurements" of the Flores & Ambrósio (2004)
slider-crank made by a model that shares no code with jaxdeploy.

The slider position x_s [m] of the independent minimal-coordinate reference
(`tests/independent/slider_crank_minimal.py`: classical Lankarani–Nikravesh rule, c = 0.5 mm,
c_e = 0.9, μ = 0; scipy DOP853 at rtol 1e-12 with every contact onset and separation located)
sampled every 20 µs over 0–4 ms, plus white Gaussian noise of σ = 1 µm (seed 2026), which the
file states on its `# sigma_slider_x` line. Run from the repository root:

    python experiments/slider_crank_measurements.py
"""

import os
import sys

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), os.pardir)
sys.path.insert(0, os.path.join(ROOT, "tests"))

from independent.slider_crank_minimal import SliderCrankMinimal  # noqa: E402

PATH = os.path.join(ROOT, "examples", "slider_crank_slider_x.csv")
SIGMA = 1e-6  # [m]
TS = np.linspace(0.0, 4e-3, 201)  # [s]
SEED = 2026


def main():
    model = SliderCrankMinimal({"clearance": 0.5e-3, "restitution": 0.9})
    solution = model.solve(float(TS[-1]), rtol=1e-12)
    x = solution.sample(TS)[:, 1]
    noisy = x + SIGMA * np.random.default_rng(SEED).standard_normal(TS.size)
    lines = [
        "# slider position of the Flores & Ambrosio (2004) slider-crank, c = 0.5 mm, c_e = 0.9,",
        "# from tests/independent/slider_crank_minimal.py (classical Lankarani-Nikravesh rule)",
        "# plus white noise; made by experiments/slider_crank_measurements.py",
        f"# sigma_slider_x = {SIGMA!r}",
        "t,slider_x",
        *(f"{t:.6g},{y:.12g}" for t, y in zip(TS, noisy, strict=True)),
    ]
    os.makedirs(os.path.dirname(PATH), exist_ok=True)
    with open(PATH, "w", encoding="utf-8") as fh:
        fh.write("\n".join(lines) + "\n")
    print(f"wrote {os.path.normpath(PATH)}: {TS.size} samples, {len(solution.onsets)} impacts")


if __name__ == "__main__":
    main()
