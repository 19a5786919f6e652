"""`jaxdeploy scenes`: every scene's parameters and options are discoverable, the options
described are the constructors' own, and a parameter the configuration ignores is refused with
what would make it used (issue 22 item 1)."""

import inspect

import pytest

from jaxdeploy.cli import main
from jaxdeploy.scenes import SCENES


@pytest.mark.parametrize("name", sorted(SCENES))
def test_option_specs_are_the_constructor_keywords_with_their_defaults(name):
    cls = SCENES[name]
    signature = inspect.signature(cls.__init__)
    kinds = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    keywords = {
        k: p.default for k, p in signature.parameters.items() if k != "self" and p.kind in kinds
    }
    assert set(cls.option_specs) == set(keywords), name
    scene = cls()
    for key, spec in cls.option_specs.items():
        assert scene.options[key] == spec.default, (name, key)
        if spec.choices:
            assert spec.default in spec.choices, (name, key)
            for choice in spec.choices:  # every listed choice builds the scene
                cls(**{key: choice})


@pytest.mark.parametrize("name", sorted(SCENES))
def test_scenes_command_lists_every_parameter_with_unit_range_and_meaning(name, capsys):
    assert main(["scenes", name]) == 0
    text = capsys.readouterr().out
    for param, spec in SCENES[name]().params.items():
        line = next(li for li in text.splitlines() if li.split()[:1] == [param])
        assert (spec.unit or "-") in line and spec.doc.split()[0] in line, line
    for option in SCENES[name].option_specs:
        assert f"  {option} " in text
    assert "default step control" in text and "default end time" in text


def test_scenes_command_lists_the_scenes_and_refuses_unknown_ones(capsys):
    assert main(["scenes"]) == 0
    out = capsys.readouterr().out
    assert all(name in out for name in SCENES)
    assert main(["scenes", "trebuchet"]) == 2
    assert "unknown scene 'trebuchet'" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv, words",
    [
        (
            ["simulate", "impact", "--set", "restitution=0.5"],
            ["--set restitution", "damping=none", "--scene-option damping=<one of", "flores"],
        ),
        (
            ["simulate", "impact", "--scene-option", "damping=flores", "--set",
             "material_damping=0.1"],
            ["material_damping", "damping=hunt_crossley_material"],
        ),
        (
            ["simulate", "slider_crank", "--scene-option", "ideal=true", "--set",
             "clearance=1e-4"],
            ["--set clearance", "ideal=false"],
        ),
        (
            ["sweep", "--scene", "impact", "--grid", "restitution=0.5,0.7"],
            ["--grid restitution", "damping"],
        ),
        (
            # optimize takes --scene-option since 61e187c: the ideal array has no hinge
            # roughness, so the default design parameters are refused by name.
            ["optimize", "--scene", "deploy_array", "--scene-option", "ideal=true"],
            ["--param", "unknown parameter 'panel1_ra'", "deploy_array"],
        ),
    ],
)  # fmt: skip
def test_a_parameter_the_configuration_ignores_is_refused(argv, words, tmp_path, capsys):
    out = tmp_path / "out"
    assert main([*argv, "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert all(w in err for w in words), err
    assert not out.exists()


def test_a_used_parameter_is_not_refused():
    # The same parameter with the option that uses it: no complaint.
    impact = SCENES["impact"](damping="lankarani_nikravesh")
    assert "restitution" not in impact.ignored_params()
    assert SCENES["slider_crank"]().ignored_params() == {}
    assert "panel1_ra" not in SCENES["deploy_array"]().ignored_params()
    assert "restitution" in SCENES["deploy_array"](ideal=True).ignored_params()
