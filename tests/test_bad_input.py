"""Bad input is refused before any work is done, with the parameter, its value and the valid
range in the message (issue 8, item 3)."""

import math

import numpy as np
import pytest

from jaxdeploy import contact
from jaxdeploy.cli import main
from jaxdeploy.mechanism import (
    AssemblyError,
    Body,
    Mechanism,
    Revolute,
    RevoluteClearance,
    consistent_state,
)
from jaxdeploy.scenes import DeployArray, SliderCrank


@pytest.fixture
def no_solver(monkeypatch):
    """Fail the test if a refused run reaches the (compiled) solver."""
    import jaxdeploy.simulation

    def forbidden(*args, **kwargs):
        raise AssertionError("simulate() was called for input that should have been refused")

    monkeypatch.setattr(jaxdeploy.simulation, "simulate", forbidden)


CLI_CASES = [
    # (scene, assignment, parameter, value as printed, valid range as printed)
    ("slider_crank", "clearance=0", "clearance", "0.0", "[1e-09, 0.1] m"),
    ("slider_crank", "clearance=-1e-6", "clearance", "-1e-06", "[1e-09, 0.1] m"),
    ("deploy_array", "panel1_clearance=0", "panel1_clearance", "0.0", "[1e-09, 0.01] m"),
    ("deploy_array", "panel2_ra=-1e-7", "panel2_ra", "-1e-07", "[0, 0.0001] m"),
    ("slider_crank", "sigma=-2e-6", "sigma", "-2e-06", "[0, 0.0001] m"),
    ("slider_crank", "poisson_ratio=0.5", "poisson_ratio", "0.5", "(-1, 0.5)"),
    ("deploy_array", "poisson_ratio=-1", "poisson_ratio", "-1.0", "(-1, 0.5)"),
    ("slider_crank", "poisson_ratio=0.7", "poisson_ratio", "0.7", "(-1, 0.5)"),
    ("slider_crank", "restitution=0", "restitution", "0.0", "(0, 1]"),
    ("deploy_array", "restitution=1.01", "restitution", "1.01", "(0, 1]"),
    ("slider_crank", "clearance=nan", "clearance", "nan", "[1e-09, 0.1] m"),
    # Below the continuum floor (scenes/_contact.py, CLEARANCE_FLOOR): refused, not run.
    ("slider_crank", "clearance=1e-300", "clearance", "1e-300", "[1e-09, 0.1] m"),
    ("impact", "impact_speed=inf", "impact_speed", "inf", "(0, 100] m/s"),
    ("deploy_array", "youngs_modulus=1e5", "youngs_modulus", "100000.0", "[1e+06, 1e+13] Pa"),
    ("deploy_array", "friction_coefficient=-0.1", "friction_coefficient", "-0.1", "[0, 2]"),
]


@pytest.mark.parametrize("scene, assignment, name, shown, valid", CLI_CASES)
def test_cli_refuses_out_of_range_parameters(
    scene, assignment, name, shown, valid, tmp_path, capsys, no_solver
):
    out = tmp_path / "run"
    assert main(["simulate", scene, "--set", assignment, "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert f"{name} = {shown}" in err, err
    assert valid in err, err
    assert not out.exists(), "a refused run must not create its output folder"


def test_cli_refuses_unknown_names_with_the_valid_ones(tmp_path, capsys, no_solver):
    assert main(["simulate", "deploy_arrray", "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err
    assert "unknown scene 'deploy_arrray'" in err and "deploy_array" in err
    assert main(["simulate", "deploy_array", "--set", "panel3_ra=1e-6", "--out", "x"]) == 2
    err = capsys.readouterr().err
    assert "unknown parameter 'panel3_ra'" in err and "panel1_ra" in err and "panel2_ra" in err


def test_cli_refuses_non_numbers_and_bad_times(tmp_path, capsys, no_solver):
    assert main(["simulate", "pendulum", "--set", "length=abc", "--out", str(tmp_path / "a")]) == 2
    assert "'abc' is not a number" in capsys.readouterr().err
    for t_end in ("0", "-1", "nan", "inf"):
        out = tmp_path / f"t{t_end}"
        assert main(["simulate", "pendulum", "--t-end", t_end, "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert "--t-end" in err and "(0, inf) s" in err
        assert not out.exists()
    assert main(["simulate", "pendulum", "--n-save", "1", "--out", str(tmp_path / "n")]) == 2
    assert "--n-save = 1" in capsys.readouterr().err


def test_cli_refuses_a_crank_as_long_as_its_rod(tmp_path, capsys, no_solver):
    out = tmp_path / "sc"
    code = main(
        ["simulate", "slider_crank", "--set", "crank_length=0.2", "--out", str(out), "--quiet"]
    )
    assert code == 2
    err = capsys.readouterr().err
    assert "crank_length = 0.2 m" in err and "(0, 0.12) m" in err
    assert not out.exists()


def test_cli_refuses_before_compiling_when_the_folder_holds_results(tmp_path, capsys, no_solver):
    out = tmp_path / "old"
    out.mkdir()
    (out / "summary.json").write_text("{}")
    assert main(["simulate", "pendulum", "--out", str(out), "--quiet"]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert (out / "summary.json").read_text() == "{}"
    a_file = tmp_path / "file"
    a_file.write_text("x")
    assert main(["simulate", "pendulum", "--out", str(a_file), "--quiet"]) == 2
    assert "not a folder" in capsys.readouterr().err


# --- the Python API ----------------------------------------------------------------------------


def _law():
    return contact.Undamped(contact.HertzElastic(1e10))


@pytest.mark.parametrize("value", [0.0, -1e-6, math.nan])
def test_clearance_joint_refuses_nonpositive_or_nan_clearance(value):
    with pytest.raises(ValueError, match=r"clearance = .* m is invalid: .*\(0, inf\] m"):
        RevoluteClearance(
            "ground", "O", "b", "c", clearance=value, journal_radius=5e-3, normal=_law()
        )


def test_clearance_joint_refuses_zero_eccentricity_smoothing():
    with pytest.raises(ValueError, match=r"eccentricity_smoothing = 0.0 m .*\(0, inf\]"):
        RevoluteClearance(
            "ground",
            "O",
            "b",
            "c",
            clearance=1e-5,
            journal_radius=5e-3,
            normal=_law(),
            eccentricity_smoothing=0.0,
        )


def test_journal_larger_than_its_bearing_is_refused():
    assert float(contact.radial_clearance(10e-3, 9.5e-3)) == pytest.approx(0.5e-3, rel=1e-12)
    with pytest.raises(ValueError, match=r"radius_journal = 0.0101 m .*\(0, 0.01\) m"):
        contact.radial_clearance(10e-3, 10.1e-3)
    with pytest.raises(ValueError, match=r"radius_journal = 0.01 m"):
        contact.radial_clearance(10e-3, 10e-3)
    with pytest.raises(ValueError, match=r"radius_bearing = -0.01 m"):
        contact.radial_clearance(-10e-3, 5e-3)


@pytest.mark.parametrize("nu", [0.5, -1.0, 0.7, math.nan])
def test_poisson_ratio_outside_its_range_is_refused(nu):
    with pytest.raises(ValueError, match=r"nu_journal = .* is invalid: .*\(-1, 0.5\)"):
        contact.journal_bearing_stiffness(5e-3, 1e-5, 2e11, nu, 2e11, 0.3)


@pytest.mark.parametrize(
    "law",
    [
        contact.HuntCrossley,
        contact.LankaraniNikravesh,
        contact.Flores,
        contact.Gonthier,
        contact.HuGuo,
    ],
)
@pytest.mark.parametrize("c_e", [0.0, -0.5, 1.0 + 1e-9, math.nan])
def test_restitution_outside_0_1_is_refused(law, c_e):
    with pytest.raises(ValueError, match=r"restitution = .* is invalid: .*\(0, 1\]"):
        law(elastic=contact.HertzElastic(1e10), restitution=c_e)


def test_roughness_and_stiffness_refusals_name_the_value():
    with pytest.raises(ValueError, match=r"sigma = -1e-06 m is invalid: .*\[0, inf\] m"):
        contact.RoughElastic(1e10, -1e-6)
    with pytest.raises(ValueError, match=r"ra = -1e-06 m is invalid"):
        contact.ra_to_sigma(-1e-6)
    with pytest.raises(ValueError, match=r"stiffness = nan N/m\^n is invalid"):
        contact.HertzElastic(math.nan)
    with pytest.raises(ValueError, match=r"E_bearing = 0.0 Pa is invalid"):
        contact.effective_modulus(2e11, 0.3, 0.0, 0.3)
    with pytest.raises(ValueError, match=r"mu = -0.1 is invalid"):
        contact.SmoothCoulomb(-0.1)


def test_scene_refuses_nan_and_names_the_range_before_building():
    with pytest.raises(ValueError, match=r"panel1_ra = nan m is invalid: .*\[0, 0.0001\] m"):
        DeployArray().resolve_params({"panel1_ra": float("nan")})
    with pytest.raises(ValueError, match=r"crank_length = 0.12 m is invalid"):
        SliderCrank().resolve_params({"crank_length": 0.12})


def test_unassemblable_pose_names_the_residual_and_the_joint():
    # Ground span 5 m, links 1 + 2 + 1.5 m: the loop cannot close.
    links = [
        Body("crank", 1.0, 0.1, {"a": (-0.5, 0.0), "b": (0.5, 0.0)}),
        Body("coupler", 1.0, 0.1, {"a": (-1.0, 0.0), "b": (1.0, 0.0)}),
        Body("rocker", 1.0, 0.1, {"a": (-0.75, 0.0), "b": (0.75, 0.0)}),
    ]
    joints = [
        Revolute("ground", "A", "crank", "a"),
        Revolute("crank", "b", "coupler", "a"),
        Revolute("coupler", "b", "rocker", "b"),
        Revolute("ground", "D", "rocker", "a"),
    ]
    mech = Mechanism(links, joints, {"A": (0.0, 0.0), "D": (5.0, 0.0)})
    guess = np.array([0.5, 0, 0, 2.0, 0, 0, 4.25, 0, 0], dtype=float)
    with pytest.raises(
        AssemblyError, match=r"constraint residual .*largest violation .* in element \d+ \(Revolute"
    ):
        consistent_state(mech, guess)


@pytest.mark.parametrize(
    "options, name",
    [
        ({"rtol": -1e-6}, "rtol"),
        ({"rtol": 0.0}, "rtol"),
        ({"rtol": 2.0}, "rtol"),
        ({"rtol": 1e-6, "atol": 0.0}, "atol"),
        ({"rtol": 1e-6, "atol": float("nan")}, "atol"),
        ({"rtol": 1e-6, "dt_max": -1e-3}, "dt_max"),
        ({"rtol": 1e-6, "dt_min": -1e-9}, "dt_min"),
        ({"rtol": 1e-6, "dt_min": 1e-3, "dt_max": 1e-4}, "dt_min"),
        ({"dt": 1e-4, "max_steps": 0}, "max_steps"),
    ],
)
def test_simulate_refuses_bad_step_control_before_compiling(options, name, monkeypatch):
    import jaxdeploy.simulation
    from jaxdeploy.scenes import Pendulum
    from jaxdeploy.simulation import simulate

    def forbidden(*args, **kwargs):
        raise AssertionError("the solver was compiled for input that should have been refused")

    monkeypatch.setattr(jaxdeploy.simulation, "_solve", forbidden)
    scene = Pendulum()
    params = scene.resolve_params()
    mech = scene.build(params)
    with pytest.raises(ValueError, match=rf"^{name} = "):
        simulate(mech, scene.initial_state(params, mech), 0.1, **options)


@pytest.fixture
def nothing_compiled(monkeypatch):
    """Fail the test if a refused command reaches a compiled solve (single run or batch)."""
    import jaxdeploy.simulation
    import jaxdeploy.sweep

    def forbidden(*args, **kwargs):
        raise AssertionError("a solver was compiled for input that should have been refused")

    monkeypatch.setattr(jaxdeploy.simulation, "_solve", forbidden)
    monkeypatch.setattr(jaxdeploy.sweep, "batch_function", forbidden)


@pytest.mark.parametrize(
    "command",
    [
        ["sweep", "--scene", "deploy_arrray", "--grid", "restitution=0.5,0.9"],
        ["optimize", "--scene", "deploy_arrray"],
        ["fit", "data.csv", "--scene", "deploy_arrray", "--params", "restitution"],
    ],
)
def test_every_command_refuses_an_unknown_scene_naming_the_valid_ones(
    command, tmp_path, capsys, nothing_compiled
):
    out = tmp_path / "out"
    command = [str(tmp_path / c) if c == "data.csv" else c for c in command]
    assert main([*command, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "unknown scene 'deploy_arrray'" in err and "deploy_array" in err, err
    assert not out.exists()


@pytest.mark.parametrize(
    "grid, expected",
    [
        ("panel3_ra=1e-6,2e-6", ["unknown parameter 'panel3_ra'", "panel1_ra", "panel2_ra"]),
        ("restitution=0.5,1.5", ["restitution = 1.5", "(0, 1]"]),
        ("panel1_clearance=0,1e-5", ["panel1_clearance = 0.0", "[1e-09, 0.01] m"]),
    ],
)
def test_sweep_refuses_unknown_or_out_of_range_grid_values_before_compiling(
    grid, expected, tmp_path, capsys, nothing_compiled
):
    out = tmp_path / "sweep"
    code = main(["sweep", "--scene", "deploy_array", "--grid", grid, "--out", str(out), "--quiet"])
    assert code == 2
    err = capsys.readouterr().err
    assert all(text in err for text in expected), err
    assert not out.exists()
