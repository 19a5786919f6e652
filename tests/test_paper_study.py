"""experiments/paper_study.py's uncertainty and readings, on synthetic numbers: each number's
error bar is the larger of its tolerance change and its round-off change (the tight run
compiled for another instruction set), and the sensitivity check's reading says what the
numbers say."""

from __future__ import annotations

import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(__file__)), "experiments"))
import paper_study as ps  # noqa: E402


def _results(tight, default, roundoff=None):
    """One variant ("default") with one case, metrics given as dicts."""
    out = {("default", "tight"): [(None, tight)], ("default", "default"): [(None, default)]}
    if roundoff is not None:
        out[("default", ps.ROUNDOFF)] = [(None, roundoff)]
    return out


def test_the_error_bar_is_the_larger_of_tolerance_and_round_off():
    results = _results({"a": 10.0, "b": 5.0}, {"a": 10.5, "b": 5.01}, {"a": 10.1, "b": 4.0})
    ev = ps.evidence(results)["default"]
    assert ev.uncertainty("a", 0) == pytest.approx(0.5)  # the tolerance's change
    assert ev.uncertainty("b", 0) == pytest.approx(1.0)  # the round-off's
    assert ps.roundoff_share(results) == (1, 2)
    alone = ps.evidence(_results({"a": 10.0}, {"a": 10.5}))["default"]
    assert alone.uncertainty("a", 0) == pytest.approx(0.5)  # no round-off run: as before
    assert ps.roundoff_share(_results({"a": 10.0}, {"a": 10.5})) == (0, 0)


def test_a_round_off_run_needs_its_build_and_a_plain_run_refuses_it(tmp_path, monkeypatch):
    monkeypatch.setattr(ps, "CACHE", tmp_path)
    monkeypatch.delenv("XLA_FLAGS", raising=False)
    with pytest.raises(RuntimeError, match="needs XLA_FLAGS with --xla_cpu_max_isa=SSE4_2"):
        ps.run("default", ps.ROUNDOFF)
    monkeypatch.setenv("XLA_FLAGS", ps.ROUNDOFF_FLAG)
    with pytest.raises(RuntimeError, match="needs XLA_FLAGS without"):
        ps.run("default", "tight")


def _sens(lock_spring, lock_clearance):
    """Synthetic sensitivities: jacobian[k][j] over OUTPUTS × SENS_PARAMS, differences for
    CD_PARAMS; every ratio 1 unless set."""
    params = list(ps.SENS_PARAMS)
    jac = [[1.0] * len(params) for _ in ps.OUTPUTS]
    jac[0][params.index("spring stiffness")] = lock_spring
    jac[0][params.index("clearance")] = lock_clearance
    for k in (3, 4):  # post-lock: far from their differences
        jac[k][params.index("spring stiffness")] = 500.0
        jac[k][params.index("clearance")] = -2000.0
    cd = {p: [1.0] * len(ps.OUTPUTS) for p in ps.CD_PARAMS}
    return {"outputs": list(ps.OUTPUTS), "params": params, "jacobian": jac,
            "central_difference": cd}  # fmt: skip


def test_the_sensitivity_reading_follows_the_numbers():
    text = ps.sensitivity_reading(_sens(1.01, -3.0))
    assert "is 1.01 times its central difference, within 5 %" in text
    assert "In the clearance it is -3 s against a difference of 1 s" in text
    assert "Of the post-lock outputs' 6 derivatives, 4 are 10 or more" in text
    assert "(up to 2e+03×)" in text and "J1 peak contact force [N] in the clearance (1×)" in text
    text = ps.sensitivity_reading(_sens(1.2, 1.02))
    assert "off by more than 5 %" in text and "In the clearance it matches as well" in text
