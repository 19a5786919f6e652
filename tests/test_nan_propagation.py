"""Failure is visible (issue 19 item 5). A NaN state gives NaN out of every contact law: a
comparison with NaN is false, so a `where`/`maximum` that picks a branch on it would turn a
broken state into a plausible force (the rough law gave 317 N at a NaN penetration, Hertz gave
0). A run that goes NaN stops and reports the time it reached."""

import inspect

import diffrax as dfx
import jax.numpy as jnp
import numpy as np
import pytest

from jaxdeploy import contact
from jaxdeploy.mechanism import Body, Mechanism, RevoluteClearance
from jaxdeploy.mechanism.element import AbstractElement, Wrench
from jaxdeploy.scenes.pendulum import Pendulum
from jaxdeploy.simulation import simulate

NAN = float("nan")
STIFFNESS = 1e10  # N/m^1.5


def _concrete(base):
    """Every concrete (non-abstract) law class exported by `jaxdeploy.contact` deriving from
    `base`: a law added later is checked without editing this file."""
    return [
        cls
        for name in contact.__all__
        if inspect.isclass(cls := getattr(contact, name))
        and issubclass(cls, base)
        and not inspect.isabstract(cls)
    ]


ELASTIC = {
    "hertz": contact.HertzElastic(STIFFNESS),
    "rough": contact.RoughElastic(STIFFNESS, 1e-6),
    "rough_sigma_0": contact.RoughElastic(STIFFNESS, 0.0),
    "rough_offset": contact.RoughElastic(STIFFNESS, 1e-6, offset=3.0),
}


def _normal_law(cls, elastic):
    if issubclass(cls, contact.AbstractRestitutionLaw):
        return cls(elastic=elastic, restitution=0.9)
    if cls is contact.HuntCrossleyMaterial:
        return cls(elastic, 0.2)
    return cls(elastic)


def _friction_law(cls):
    if cls is contact.StribeckFriction:
        return cls(mu_static=0.15, mu_kinetic=0.1, stribeck_velocity=1e-2)
    return cls(mu=0.1)


def test_every_law_is_covered():
    names = {c.__name__ for c in _concrete(contact.AbstractNormalLaw)}
    assert {"HuntCrossley", "LankaraniNikravesh", "Undamped", "HuntCrossleyMaterial"} <= names
    assert len(_concrete(contact.AbstractFrictionLaw)) >= 3
    assert len(_concrete(contact.AbstractElasticLaw)) >= 2


@pytest.mark.parametrize("name", sorted(ELASTIC))
def test_elastic_laws_give_nan_at_a_nan_penetration(name):
    law = ELASTIC[name]
    # In contact, in the gap, and NaN, side by side: only the NaN entry is NaN.
    delta = jnp.array([2e-6, -1e-3, NAN])
    for quantity in (law.force, law.stiffness, law.potential):
        values = np.asarray(quantity(delta))
        assert np.all(np.isfinite(values[:2])), (name, quantity.__name__, values)
        assert np.isnan(values[2]), (name, quantity.__name__, values)


@pytest.mark.parametrize("cls", _concrete(contact.AbstractNormalLaw), ids=lambda c: c.__name__)
@pytest.mark.parametrize("elastic", ["hertz", "rough"])
def test_normal_laws_give_nan_when_any_input_is_nan(cls, elastic):
    law = _normal_law(cls, ELASTIC[elastic])
    uses_rate = cls is not contact.Undamped
    uses_memory = cls.needs_impact_velocity
    for delta in (2e-6, -1e-3):  # in contact and in the gap (a NaN rate still counts there)
        finite = law.force(delta, 0.1, 0.2)
        assert np.isfinite(float(finite))
        assert np.isnan(float(law.force(NAN, 0.1, 0.2))), (cls.__name__, delta)
        if uses_rate:
            assert np.isnan(float(law.force(delta, NAN, 0.2))), (cls.__name__, delta)
        if uses_memory:
            assert np.isnan(float(law.force(delta, 0.1, NAN))), (cls.__name__, delta)


@pytest.mark.parametrize("cls", _concrete(contact.AbstractFrictionLaw), ids=lambda c: c.__name__)
def test_friction_laws_give_nan_when_any_input_is_nan(cls):
    law = _friction_law(cls)
    assert np.isfinite(float(law.force(0.01, 10.0)))
    assert np.isnan(float(law.force(NAN, 10.0)))
    assert np.isnan(float(law.force(0.01, NAN)))
    # At rest the regularised sign is 0, and a NaN normal force must still show.
    assert np.isnan(float(law.force(0.0, NAN)))


def test_lugre_friction_gives_nan_when_any_input_is_nan():
    """LuGre (a law with its own state z, not an `AbstractFrictionLaw`)."""
    law = contact.LuGreFriction()
    args = (0.01, 1e-7, 10.0)  # v [m/s], z [m], F_N [N]
    for method in (law.force, law.rate):
        assert np.isfinite(float(method(*args)))
        for k in range(3):
            broken = list(args)
            broken[k] = NAN
            assert np.isnan(float(method(*broken))), (method.__name__, k)
    assert np.isnan(float(law.force(0.0, 1e-7, NAN)))  # at rest too


def test_gaussian_moments_give_nan_at_nan():
    h = jnp.array([-20.0, 0.5, 70.0, NAN])
    for n in (0.0, 1.0, 1.5, 2.5):
        values = np.asarray(contact.gaussian_moment(h, n))
        assert np.all(np.isfinite(values[:3])) and np.isnan(values[3]), (n, values)
        smoothed = np.asarray(contact.gaussian_smoothed_power(h * 1e-6, 1e-6, n))
        assert np.all(np.isfinite(smoothed[:3])) and np.isnan(smoothed[3]), (n, smoothed)
    for n in (0.0, 0.5, 1.5):
        powers = np.asarray(contact.positive_power(jnp.array([-1.0, 0.0, 2.0, NAN]), n))
        assert np.all(np.isfinite(powers[:3])) and np.isnan(powers[3]), (n, powers)


@pytest.mark.parametrize("elastic", ["hertz", "rough"])
def test_clearance_joint_forces_are_nan_at_a_nan_state(elastic):
    """The joint (geometry, both sides of the bore, friction) keeps a NaN coordinate's NaN."""
    normal = contact.LankaraniNikravesh(elastic=ELASTIC[elastic], restitution=0.9)
    joint = RevoluteClearance(
        "ground",
        "B",
        "journal",
        "c",
        clearance=1e-4,
        journal_radius=5e-3,
        normal=normal,
        friction=contact.SmoothCoulomb(mu=0.1),
    )
    mech = Mechanism([Body("journal", 1.0, 1e-5, {"c": (0.0, 0.0)})], [joint], {"B": (0.0, 0.0)})
    q = jnp.array([1.2e-4, 0.0, 0.0])
    v = jnp.array([0.1, 0.0, 0.0])
    memory = mech.init_memory(q, v)[0]
    fn, ft, _ = joint.contact_forces(mech.kinematics(q, v), memory)
    assert np.isfinite(float(fn)) and float(fn) > 0 and np.isfinite(float(ft))
    for broken in (q.at[0].set(NAN), q.at[2].set(NAN)):
        fn, ft, _ = joint.contact_forces(mech.kinematics(broken, v), memory)
        assert np.isnan(float(fn)) and np.isnan(float(ft))
    fn, ft, _ = joint.contact_forces(mech.kinematics(q, v.at[1].set(NAN)), memory)
    assert np.isnan(float(fn)) and np.isnan(float(ft))


# --- a run that goes NaN stops and says when ---------------------------------------------------


class _NaNAfter(AbstractElement):
    """A force that turns NaN after `time` [s]: a vector field that breaks mid-run."""

    body: str
    time: float

    def bodies(self):
        return (self.body,)

    def wrenches(self, kin, t, memory):
        f = jnp.where(t > self.time, jnp.nan, 0.0)
        return [Wrench(self.body, force=jnp.stack([f, 0.0 * f]))]


T_NAN = 2e-3  # s


@pytest.fixture(scope="module")
def breaking_pendulum():
    scene = Pendulum()
    params = scene.resolve_params({"initial_angle": -1.0})
    mech = scene.build(params)
    mech = Mechanism(mech.bodies, (*mech.elements, _NaNAfter("rod", T_NAN)), mech.ground_points)
    return mech, scene.initial_state(params, mech)


@pytest.mark.parametrize(
    "control",
    [
        dict(solver="tsit5", rtol=1e-8, atol=1e-10),
        dict(rtol=1e-8, atol=1e-10),
        dict(solver="tsit5", dt=1e-4),
        dict(dt=1e-4),
    ],
    ids=["tsit5-adaptive", "gen-alpha-adaptive", "tsit5-fixed", "gen-alpha-fixed"],
)
def test_a_run_that_goes_nan_stops_there_with_the_time(breaking_pendulum, control):
    """Before: adaptive runs crept towards T_NAN until `max_steps` (reported as that), and a
    fixed-step Tsit5 run integrated NaN to the end and reported success. Now every path stops
    with `nonfinite` at the last finite state, within one step of T_NAN, and the time reached
    lies between two saved times (saves every 4 ms: the last one is t = 0)."""
    mech, s0 = breaking_pendulum
    tr = simulate(mech, s0, 8e-3, n_save=3, max_steps=100_000, **control)
    assert tr.result == dfx.RESULTS.nonfinite, tr.status()
    step = control.get("dt", 1e-4)
    assert T_NAN - step - 1e-12 <= tr.time_reached() <= T_NAN + 1e-12, tr.time_reached()
    assert tr.status().startswith(f"failed after t = {tr.time_reached():.6g} s: Nonfinite")
    assert int(tr.stats["num_steps"]) < 1000  # stopped, not ground down to max_steps
    saved = np.isfinite(np.asarray(tr.ts))
    assert saved.sum() == 1 and np.all(np.isfinite(np.asarray(tr.q)[saved]))


def test_time_reached_is_the_end_of_a_successful_run(breaking_pendulum):
    mech, s0 = breaking_pendulum
    tr = simulate(mech, s0, 1.5e-3, n_save=4, solver="tsit5", rtol=1e-8, atol=1e-10)
    assert tr.ok and tr.time_reached() == 1.5e-3
