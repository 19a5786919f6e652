"""`jaxdeploy simulate` makes the ideal-joint reference in a second thread beside the run, at
the saved times the run will have; what it returns must be what the command made before, when
it computed the reference after the run at the run's own saved times."""

import threading

import numpy as np
import pytest

from jaxdeploy.commands import simulate as command
from jaxdeploy.commands._phases import Phases


@pytest.fixture
def calls(monkeypatch):
    """`_reference` replaced by a recorder: (saved times, thread) of every call."""
    made = []

    def fake(scene, params, ts, phases):
        made.append((np.asarray(ts).copy(), threading.current_thread().name))
        if scene == "failing":
            raise RuntimeError("reference failed")
        return ("reference at", tuple(np.asarray(ts)))

    monkeypatch.setattr(command, "_reference", fake)
    return made


def test_the_reference_made_beside_is_used_when_the_run_saved_where_expected(calls):
    ts = np.linspace(0.0, 1.0, 5)
    beside = command._ReferenceBeside("scene", {}, ts, Phases(quiet=True))
    beside.start()
    assert beside.result(ts.copy()) == ("reference at", tuple(ts))
    assert len(calls) == 1 and calls[0][1] == "reference"  # made once, in its own thread


def test_other_saved_times_get_a_reference_made_at_them(calls):
    """A failed run's unreached saves are not the expected times: the reference is then made
    at the run's own times, as before, and the one made beside is not used."""
    expected = np.linspace(0.0, 1.0, 5)
    actual = np.array([0.0, 0.25, 0.5, np.inf, np.inf])
    beside = command._ReferenceBeside("scene", {}, expected, Phases(quiet=True))
    out = beside.result(actual)
    assert out[1][:3] == (0.0, 0.25, 0.5) and np.isinf(out[1][3])
    assert [name for _, name in calls] == ["reference", threading.current_thread().name]


def test_an_error_beside_is_raised_where_the_reference_is_used(calls):
    ts = np.linspace(0.0, 1.0, 3)
    beside = command._ReferenceBeside("failing", {}, ts, Phases(quiet=True))
    beside.start()
    with pytest.raises(RuntimeError, match="reference failed"):
        beside.result(ts)
