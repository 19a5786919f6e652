"""Reference solutions: converged (independent tight runs agree) and equal to an independent
model (numpy right-hand side, exact onset events, scipy DOP853)."""

import numpy as np

from jaxdeploy.benchmarks.peers import SliderCrankNumpy
from jaxdeploy.benchmarks.reference import eccentricities, reference_solution
from jaxdeploy.scenes import SliderCrank

T_END = 0.45e-3  # through the first impact (onset ≈ 0.23 ms, separation < 0.33 ms)


def test_reference_converged_and_matches_independent_model():
    ref = reference_solution("slider_crank", t_end=T_END, n_save=46, rtol=1e-10)
    assert ref.window_end == T_END
    window, full = ref.error_bound
    # Dopri8 and Tsit5 at 1e-9 agree with the 1e-10 reference to < 1e-7 c (0.05 nm).
    assert window < 1e-7 and full < 1e-7, ref.evidence
    assert {e["solver"] for e in ref.evidence} == {"dopri8", "tsit5"}

    scene = SliderCrank()
    mech = scene.build(ref.params)
    s0 = scene.initial_state(ref.params, mech)
    model = SliderCrankNumpy(ref.params)
    peer = model.solve(s0, T_END, ref.ts, "DOP853", 1e-12, 1e-14)
    assert peer.ok and [kind for _, kind, _ in peer.events] == ["onset", "peak", "separation"]
    diff = np.linalg.norm(
        eccentricities(mech, ref.q) - eccentricities(mech, peer.ys[:, :9]), axis=-1
    )
    assert np.max(diff) < 1e-6, np.max(diff)
