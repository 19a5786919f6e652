"""Any parameter can be held: the clearance joint's sizes are parameterised as users measure
them (journal and clearance, bore and clearance, bore and journal), and a parameter the scene's
options make irrelevant is refused by `fit`, naming the option that makes it count."""

import pytest

from jaxdeploy.cli import main
from jaxdeploy.fit import make_parameters
from jaxdeploy.scenes import get_scene


def _joint(scene, params):
    mechanism = scene.build(scene.resolve_params(params))
    return next(e for e in mechanism.elements if hasattr(e, "clearance"))


@pytest.mark.parametrize(
    ("geometry", "held", "varied", "journal", "clearance"),
    [
        # bore held at 10 mm: a larger clearance is a smaller journal
        ("bore_clearance", {"bore_radius": 0.01}, {"clearance": 6e-4}, 0.0094, 6e-4),
        # journal held (the scene's historical parameterisation): the bore grows instead
        ("journal_clearance", {"journal_radius": 0.0095}, {"clearance": 6e-4}, 0.0095, 6e-4),
        # two measured radii: the clearance is their difference
        ("bore_journal", {"bore_radius": 0.0101}, {"journal_radius": 0.0095}, 0.0095, 6e-4),
    ],
)
def test_each_geometry_holds_its_size_and_derives_the_third(
    geometry, held, varied, journal, clearance
):
    scene = get_scene("slider_crank", geometry=geometry)
    assert set(held) | set(varied) <= set(scene.params)
    joint = _joint(scene, {**held, **varied})
    assert float(joint.journal_radius) == pytest.approx(journal, rel=1e-12)
    assert float(joint.clearance) == pytest.approx(clearance, rel=1e-9)
    complete = scene.complete(scene.resolve_params({**held, **varied}))
    assert complete["bore_radius"] == pytest.approx(journal + clearance, rel=1e-12)


def test_a_geometry_with_the_bore_inside_the_journal_is_refused():
    scene = get_scene("slider_crank", geometry="bore_journal")
    with pytest.raises(ValueError, match="bore must be larger than the journal"):
        scene.resolve_params({"bore_radius": 0.009, "journal_radius": 0.0095})
    # Radii 1e-12 m apart: a clearance below the continuum floor, refused as when given.
    with pytest.raises(ValueError, match="clearance ≥ 1e-09 m"):
        scene.resolve_params({"bore_radius": 0.0095 + 1e-12, "journal_radius": 0.0095})
    with pytest.raises(ValueError, match="geometry"):
        get_scene("slider_crank", geometry="diameters")
    # clearance is not a parameter when both radii are: it cannot be fitted or set
    with pytest.raises(ValueError, match="unknown parameter 'clearance'"):
        make_parameters(scene, ["clearance"])


def test_fit_refuses_a_parameter_the_options_ignore_naming_the_option(tmp_path, capsys):
    """impact's default damping is "none": restitution does not enter the run."""
    data = tmp_path / "d.csv"
    data.write_text("# sigma = 1e-6\nt,journal_x\n0,0\n1e-4,1e-4\n2e-4,1e-4\n")
    for extra in (["--params", "restitution=0.5"],
                  ["--params", "stiffness", "--set", "restitution=0.5"]):  # fmt: skip
        code = main(["fit", str(data), "--scene", "impact", *extra, "--out", str(tmp_path / "o")])
        err = capsys.readouterr().err
        assert code == 2
        assert "'restitution'" in err and "damping=" in err
        assert not (tmp_path / "o").exists()
    scene = get_scene("slider_crank", ideal=True)
    with pytest.raises(ValueError, match="ideal=false"):
        make_parameters(scene, ["clearance"])
    # with a damped law restitution counts
    assert make_parameters(get_scene("impact", damping="hunt_crossley"), ["restitution"])
