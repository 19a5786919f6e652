"""The energy meter beside a mechanism (`BalanceMeter`, `balance_metered`) books what the
meters wrapped around its elements (`metered`, `EnergyMeter`) book, bit for bit: the same
dissipated and injected energy per element and the same balance, while it keeps four arrays
instead of a copy of every metered element's memory, and changes no step."""

from typing import ClassVar

import jax.numpy as jnp
import numpy as np
import pytest

from jaxdeploy.mechanism import (
    Body,
    Mechanism,
    balance_metered,
    balance_metered_state,
    consistent_state,
    energy_balance,
    metered,
    metered_balance,
)
from jaxdeploy.mechanism.element import AbstractElement, Wrench
from jaxdeploy.scenes import get_scene
from jaxdeploy.simulation import simulate


class _SteppedSpring(AbstractElement):
    """A spring–damper pulling body `b` towards a rest position that moves by `shift` at the
    start of every step (`memory_for_step`): energy is put in between steps (the meter's
    `injected`) and the damper dissipates. Only here because no element of the package changes
    its memory between steps, which is the meter's other path."""

    stiffness: float = 40.0
    damping: float = 0.3
    shift: float = 1e-4
    has_memory: ClassVar[bool] = True

    def bodies(self):
        return ("b",)

    def init_memory(self, kin):
        return {"rest": jnp.zeros((), kin.q.dtype)}

    def memory_for_step(self, memory, kin):
        return {"rest": memory["rest"] + self.shift}

    def wrenches(self, kin, t, memory):
        force = -self.stiffness * (kin.origin("b")[0] - memory["rest"]) - self.damping * kin.v[0]
        return [Wrench("b", force=jnp.stack([force, 0.0 * force]))]

    def potential_energy(self, kin, memory):
        return 0.5 * self.stiffness * (kin.origin("b")[0] - memory["rest"]) ** 2


def _both_ways(mechanism, initial, t_end, control):
    """The balance of a run with the meter beside (`balance_metered`) and of one with meters
    wrapped around the elements (`metered`), and the two runs."""
    beside = balance_metered(mechanism)
    run = simulate(beside, balance_metered_state(beside, initial), t_end, n_save=41,
                   control=control)  # fmt: skip
    wrapped = metered(mechanism)
    state = consistent_state(wrapped, initial.q, initial.v)
    reference = simulate(wrapped, state, t_end, n_save=41, control=control)
    books = energy_balance(wrapped, reference.q, reference.v, reference.memory)
    return metered_balance(beside, run.q, run.v, run.memory), run, books, reference


def _assert_same_books(beside, wrapped):
    for key in ("kinetic", "potential", "dissipated", "injected", "residual"):
        np.testing.assert_array_equal(np.asarray(beside[key]), np.asarray(wrapped[key]), key)
    for key in ("dissipated_by", "injected_by", "potential_of"):
        assert list(beside[key]) == list(range(len(beside[key])))  # the meters, in order
        for got, want in zip(beside[key].values(), wrapped[key].values(), strict=True):
            np.testing.assert_array_equal(np.asarray(got), np.asarray(want), key)


def test_an_element_that_changes_its_memory_between_steps_is_booked_alike():
    mechanism = Mechanism([Body("b", 0.5, 0.01)], [_SteppedSpring()])
    initial = consistent_state(mechanism, jnp.array([0.01, 0.0, 0.0]))
    beside, run, wrapped, reference = _both_ways(mechanism, initial, 0.3, None)  # Tsit5
    # Energy was put in (or taken out) between steps, and the damper dissipated.
    assert float(beside["injected"][-1]) != 0 and float(beside["dissipated"][-1]) > 0
    _assert_same_books(beside, wrapped)
    np.testing.assert_array_equal(np.asarray(run.q), np.asarray(reference.q))
    meter_memory = run.memory[-1]
    assert sorted(meter_memory) == ["dissipated", "force_start", "injected", "q_start"]


@pytest.mark.slow
def test_deploy_array_is_booked_alike_through_its_contacts_and_latches():
    """deploy_array to past the lock (contacts of both clearance joints, the latches
    engaging): its five metered elements booked as the wrapped meters book them."""
    scene = get_scene("deploy_array")
    params = scene.resolve_params({})
    mechanism = scene.build(params)
    initial = scene.initial_state(params, mechanism)
    beside, run, wrapped, reference = _both_ways(mechanism, initial, 0.56, scene.default_control)
    assert float(beside["dissipated"][-1]) > 0
    _assert_same_books(beside, wrapped)
    np.testing.assert_array_equal(np.asarray(run.q), np.asarray(reference.q))
