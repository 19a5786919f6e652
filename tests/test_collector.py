"""Full garbage collections deferred while jaxdeploy's programs trace (`jaxdeploy._collector`).

The context manager must restore the thresholds it found however it is left (nested,
concurrently, by an exception), and the programs it is meant for must actually trace inside
it: a probe element and a probe loss record the threshold in force while JAX traces them.
"""

from __future__ import annotations

import gc
import threading
import uuid

import jax.numpy as jnp
import pytest

from jaxdeploy import _collector
from jaxdeploy._collector import DEFERRED_THRESHOLD, full_collections_deferred
from jaxdeploy.mechanism import Body, Gravity, Mechanism, Revolute, consistent_state
from jaxdeploy.mechanism.element import AbstractElement
from jaxdeploy.simulation import simulate


@pytest.fixture
def thresholds():
    """The process's thresholds, set to known values for the test and restored after it."""
    saved = gc.get_threshold()
    gc.set_threshold(700, 10, 10)
    yield (700, 10, 10)
    gc.set_threshold(*saved)


def test_defers_full_collections_and_restores_the_thresholds(thresholds):
    with full_collections_deferred():
        assert gc.get_threshold() == (700, 10, DEFERRED_THRESHOLD)
        with full_collections_deferred():  # nested: one adjustment
            assert gc.get_threshold() == (700, 10, DEFERRED_THRESHOLD)
        assert gc.get_threshold() == (700, 10, DEFERRED_THRESHOLD)
    assert gc.get_threshold() == thresholds
    assert _collector._depth == 0


def test_restores_the_thresholds_when_the_block_raises(thresholds):
    with pytest.raises(RuntimeError, match="inside"):
        with full_collections_deferred():
            raise RuntimeError("inside")
    assert gc.get_threshold() == thresholds
    assert _collector._depth == 0


def test_overlapping_blocks_of_two_threads_restore_the_thresholds(thresholds):
    """Thread A enters, B enters, A leaves (still deferred: B is inside), B leaves."""
    a_in, b_in, a_out = threading.Event(), threading.Event(), threading.Event()
    seen = {}

    def first():
        with full_collections_deferred():
            a_in.set()
            b_in.wait(10)
        a_out.set()

    def second():
        a_in.wait(10)
        with full_collections_deferred():
            b_in.set()
            a_out.wait(10)
            seen["after A left"] = gc.get_threshold()

    threads = [threading.Thread(target=first), threading.Thread(target=second)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(20)
    assert seen["after A left"] == (700, 10, DEFERRED_THRESHOLD)
    assert gc.get_threshold() == thresholds


class _ThresholdProbe(AbstractElement):
    """A force element that adds nothing and records the collector's full-collection
    threshold whenever its forces are traced or evaluated."""

    def wrenches(self, kin, t, memory):
        _SEEN.append(gc.get_threshold()[2])
        return []


_SEEN: list[int] = []


def _pendulum_with_probe():
    # A body name no other test uses: the program is traced here, not found in JAX's caches.
    name = f"rod_{uuid.uuid4().hex[:8]}"
    rod = Body(name, mass=1.0, inertia=1.0 / 12.0, points={"pivot": (-0.5, 0.0)})
    mechanism = Mechanism(
        [rod],
        [Revolute("ground", "O", name, "pivot"), Gravity(), _ThresholdProbe()],
        ground_points={"O": (0.0, 0.0)},
    )
    initial = consistent_state(mechanism, jnp.array([0.5, 0.0, 0.0]), fixed=(2,))
    return mechanism, initial


def test_simulate_traces_its_program_with_full_collections_deferred(thresholds):
    mechanism, initial = _pendulum_with_probe()
    _SEEN.clear()
    trajectory = simulate(mechanism, initial, 0.01, n_save=3)
    assert trajectory.ok
    assert _SEEN, "the probe's forces were never traced"
    assert set(_SEEN) == {DEFERRED_THRESHOLD}
    assert gc.get_threshold() == thresholds


def test_gradient_function_traces_with_full_collections_deferred(thresholds):
    import jax

    from jaxdeploy.fit import gradient_function
    from jaxdeploy.scenes import Pendulum

    seen = []

    def loss(channels):
        seen.append(gc.get_threshold()[2])
        return jnp.mean(channels[sorted(channels)[0]] ** 2)

    scene = Pendulum()
    for mode in ("forward", "reverse"):
        seen.clear()
        g, x0 = gradient_function(scene, {}, ["length"], loss, 0.01, mode=mode, n_save=3)
        jax.make_jaxpr(g)(x0)
        assert seen and set(seen) == {DEFERRED_THRESHOLD}, mode
        assert gc.get_threshold() == thresholds
