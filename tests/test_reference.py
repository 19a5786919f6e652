"""Reference solutions: converged (independent tight runs agree) and equal to an independent
model (numpy right-hand side, exact contact events, scipy DOP853)."""

from benchmarks.reference import reference_solution

T_END = 0.45e-3  # through the first impact (onset ≈ 0.23 ms, separation < 0.33 ms)


def test_reference_converged_and_matches_independent_model():
    ref = reference_solution("slider_crank", t_end=T_END, n_save=46, rtol=1e-10)
    assert ref.window_end == T_END
    solvers = [e["solver"] for e in ref.evidence]
    assert solvers[:2] == ["dopri8", "tsit5"] and solvers[2].startswith("numpy model")
    # Dopri8 and Tsit5 at 10× the tolerance, and the independent numpy model with
    # exact onset events agree with the reference to < 1e-7 c (0.05 nm).
    for check in ref.evidence:
        assert check["window"] < 1e-7 and check["full"] < 1e-7, check
