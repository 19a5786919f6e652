"""deploy_array's roughness couplings: each hinge's friction and restitution from its own Ra."""

import numpy as np
import pytest

from jaxdeploy.contact import PloughingFriction, RestitutionRoughnessCoupling
from jaxdeploy.mechanism import RevoluteClearance
from jaxdeploy.scenes import DeployArray

CASE = {"panel1_ra": 0.8e-6, "panel2_ra": 3.2e-6}


def _clearance_laws(scene, overrides):
    params = scene.resolve_params({**CASE, **overrides})
    mechanism = scene.build(params)
    return [e for e in mechanism.elements if isinstance(e, RevoluteClearance)]


def test_ploughing_friction_per_hinge():
    scene = DeployArray(friction_roughness="ploughing")
    joints = _clearance_laws(scene, {"friction_adhesion": 0.02, "tool_nose_radius": 1.2e-3})
    law = PloughingFriction(0.02, 1.2e-3)
    mus = [float(j.friction.mu) for j in joints]
    np.testing.assert_allclose(mus, [float(law(0.8e-6)), float(law(3.2e-6))], rtol=1e-15)
    assert mus[1] > mus[0]  # rougher hinge (panel 2) rubs harder
    assert "friction_coefficient" in scene.ignored_params()
    assert "friction_adhesion" in DeployArray().ignored_params()


def test_constant_friction_and_no_restitution_coupling_by_default():
    joints = _clearance_laws(DeployArray(), {})
    assert [float(j.friction.mu) for j in joints] == [0.05, 0.05]
    assert [float(j.normal.restitution) for j in joints] == [0.9, 0.9]


def test_restitution_coupling_per_hinge():
    joints = _clearance_laws(DeployArray(), {"restitution_roughness_exponent": 1.0})
    coupling = RestitutionRoughnessCoupling(1.6e-6, 1.0)
    expected = [float(coupling(0.9, 0.8e-6)), float(coupling(0.9, 3.2e-6))]
    np.testing.assert_allclose([float(j.normal.restitution) for j in joints], expected, 1e-15)


def test_bad_friction_roughness_names_the_option():
    with pytest.raises(ValueError, match="friction_roughness = 'x' is invalid; valid: constant"):
        DeployArray(friction_roughness="x")


def test_panel_mass_scale_scales_the_panels_only():
    scene = DeployArray()
    base = scene.build(scene.resolve_params({}))
    heavy = scene.build(scene.resolve_params({"panel_mass_scale": 1.5}))
    for b0, b1 in zip(base.bodies, heavy.bodies, strict=True):
        factor = 1.5 if b0.name.startswith("panel") else 1.0
        assert float(b1.mass) == pytest.approx(factor * float(b0.mass), rel=1e-15)
        assert float(b1.inertia) == pytest.approx(factor * float(b0.inertia), rel=1e-15)
