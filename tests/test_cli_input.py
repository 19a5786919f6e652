"""Every command checks its whole command line before it works: a malformed argument list ends
with exit code 2 and a message, no traceback, no output folder, and nothing simulated or
compiled (issue 22 item 4). The property test feeds random malformed argument lists to every
command; the examples below are the cases once seen to slip through."""

import math
import string

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from jaxdeploy.cli import main


class Compiled(Exception):
    """Raised by the stand-ins of every entry into a simulation: the input was accepted."""


@pytest.fixture
def nothing_runs(monkeypatch):
    """Replace every way a command reaches a simulation (single run, batch, sweep, design
    problem, fit) by `Compiled`."""
    import jaxdeploy.fit
    import jaxdeploy.optimize
    import jaxdeploy.simulation
    import jaxdeploy.sweep

    def forbidden(*args, **kwargs):
        raise Compiled

    monkeypatch.setattr(jaxdeploy.simulation, "_solve", forbidden)
    monkeypatch.setattr(jaxdeploy.sweep, "batch_function", forbidden)
    monkeypatch.setattr(jaxdeploy.optimize.DesignProblem, "__init__", forbidden)
    monkeypatch.setattr(jaxdeploy.fit, "fit", forbidden)
    monkeypatch.setattr(jaxdeploy.fit, "gradient_check", forbidden)
    # Building an initial state assembles the mechanism (seconds); it comes after every check.
    from jaxdeploy.scenes import SCENES

    for cls in SCENES.values():
        monkeypatch.setattr(cls, "initial_state", forbidden)


@pytest.fixture
def data_file(tmp_path):
    path = tmp_path / "data.csv"
    rows = ["t,rod_theta"] + [f"{0.01 * i},{0.001 * i}" for i in range(11)]
    path.write_text("\n".join(rows) + "\n")
    return str(path)


def _bases(data):
    """A valid argument list per command (without --out), cheap to check."""
    return {
        "simulate": ["simulate", "pendulum", "--t-end", "0.1", "--quiet"],
        "sweep": ["sweep", "--scene", "pendulum", "--grid", "length=1,2", "--t-end", "0.1"],
        "optimize": ["optimize", "--param", "panel1_ra", "--steps", "1", "--quiet"],
        "fit": ["fit", data, "--scene", "pendulum", "--params", "length", "--quiet"],
        "gradcheck": [
            "gradcheck",
            "pendulum",
            "--output",
            "x",
            "--t-end",
            "0.1",
            "--quiet",
            "--params",
            "length",
        ],
    }


# Numeric flags of each command and their valid domain: ("pos", unit) finite > 0, ("unit",)
# in (0, 1), ("int", k) integer ≥ k.
NUMERIC = {
    "simulate": {
        "--t-end": "pos",
        "--n-save": ("int", 2),
        "--rtol": "unit",
        "--atol": "pos",
        "--dt-max": "pos",
        "--dt": "pos",
    },
    "sweep": {
        "--t-end": "pos",
        "--n-save": ("int", 2),
        "--chunk-size": ("int", 1),
        "--rtol": "unit",
        "--atol": "pos",
        "--dt-max": "pos",
        "--dt": "pos",
    },
    "optimize": {
        "--t-end": "pos",
        "--n-save": ("int", 2),
        "--steps": ("int", 1),
        "--learning-rate": "pos",
        "--smoothing": "pos",
        "--pairs": ("int", 1),
        "--tol-ra": "pos",
        "--tol-clearance": "pos",
        "--rtol": "unit",
        "--atol": "pos",
        "--dt-max": "pos",
        "--dt": "pos",
    },
    "gradcheck": {
        "--t-end": "pos",
        "--n-save": ("int", 2),
        "--tolerance": "unit",
        "--derivative-change": "unit",
        "--steps": "unit",
        "--rtol": "unit",
        "--atol": "pos",
        "--dt-max": "pos",
        "--dt": "pos",
    },
    "fit": {
        "--max-iterations": ("int", 1),
        "--starts": ("int", 0),
        "--block": "pos",
        "--width": "pos",
        "--rtol": "unit",
        "--atol": "pos",
        "--dt-max": "pos",
        "--dt": "pos",
    },
}
# Repeatable NAME=VALUE flags of each command, with a valid NAME.
ASSIGNMENTS = {
    "simulate": [("--set", "length")],
    "sweep": [("--set", "mass"), ("--grid", "initial_angle")],
    "optimize": [("--set", "restitution"), ("--start", "panel1_ra")],
    "fit": [("--set", "mass")],
    "gradcheck": [("--set", "mass")],
}


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


_words = st.text(alphabet=string.ascii_letters + string.punctuation + " ", min_size=1).filter(
    lambda s: not _is_number(s) and not s.startswith("-")
)


def _bad_value(kind):
    """Values outside `kind`'s domain, as text."""
    special = st.sampled_from(["nan", "inf", "-inf", "NaN", "-1e400"])
    if kind == "pos":
        numbers = st.floats(max_value=0.0, allow_nan=False, allow_infinity=False).map(repr)
    elif kind == "unit":
        numbers = st.one_of(
            st.floats(max_value=0.0, allow_nan=False, allow_infinity=False),
            st.floats(min_value=1.0, allow_nan=False, allow_infinity=False),
        ).map(repr)
    else:
        low = kind[1]
        numbers = st.one_of(
            st.integers(max_value=low - 1).map(str),
            st.floats(allow_nan=False, allow_infinity=False)
            .filter(lambda x: x != math.floor(x))
            .map(repr),
        )
        special = st.sampled_from(["nan", "inf", "1e3", "2.5"])
    return st.one_of(numbers, special, _words)


@st.composite
def malformed(draw, command):
    """(extra arguments, what is wrong) for `command`: one defect, always an invalid one."""
    choices = ["unknown flag", "numeric", "solver", "set unknown", "set malformed"]
    if ASSIGNMENTS[command]:
        choices.append("repeated")
    if command in ("simulate", "sweep", "fit", "optimize", "gradcheck"):
        choices.append("scene")
    defect = draw(st.sampled_from(choices))
    if defect == "unknown flag":
        name = draw(st.text(alphabet=string.ascii_lowercase + "-", min_size=1, max_size=12))
        return ["--zz" + name, draw(st.sampled_from(["1", "x", "--quiet"]))], defect
    if defect == "numeric":
        flag = draw(st.sampled_from(sorted(NUMERIC[command])))
        return [flag, draw(_bad_value(NUMERIC[command][flag]))], defect
    if defect == "solver":
        name = draw(_words.filter(lambda s: s not in ("generalized_alpha", "tsit5")))
        return ["--solver", name], defect
    if defect == "set unknown":
        name = draw(st.text(alphabet=string.ascii_lowercase, min_size=1, max_size=10))
        return ["--set", f"zz{name}=1"], defect
    if defect == "set malformed":
        return ["--set", draw(st.text(alphabet=string.ascii_lowercase, min_size=1))], defect
    if defect == "repeated":
        flag, name = draw(st.sampled_from(ASSIGNMENTS[command]))
        return [flag, f"{name}=0.1", flag, f"{name}=0.2"], defect
    # scene: a name that is not a scene
    name = draw(st.text(alphabet=string.ascii_lowercase + "_", min_size=1, max_size=14))
    return ["--scene", "zz" + name], defect


def _with_scene(base, command, extra):
    """`base` + `extra`; a bad --scene for simulate replaces its positional scene."""
    if command in ("simulate", "gradcheck") and extra[:1] == ["--scene"]:
        return [base[0], extra[1], *base[2:]]
    return [*base, *extra]


def _refused(argv, out, capsys):
    code = main([*argv, "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 2, (argv, code, captured.err)
    assert captured.err.strip(), "a refusal says why"
    assert "Traceback" not in captured.err + captured.out
    assert not out.exists(), "a refused command must not create its output folder"
    return captured.err


@pytest.mark.parametrize("command", sorted(NUMERIC))
def test_random_malformed_command_lines_are_refused(
    command, tmp_path, capsys, nothing_runs, data_file
):
    base = _bases(data_file)[command]
    out = tmp_path / "out"

    @settings(
        max_examples=25,
        deadline=None,
        suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
    )
    @given(malformed(command))
    def check(case):
        extra, _ = case
        _refused(_with_scene(base, command, extra), out, capsys)

    check()


@pytest.mark.parametrize("command", sorted(NUMERIC))
def test_the_valid_command_lines_pass_every_check(command, tmp_path, nothing_runs, data_file):
    """The property above is not vacuous: its base command lines pass every check and reach
    the simulation (here a stand-in)."""
    with pytest.raises(Compiled):
        main([*_bases(data_file)[command], "--out", str(tmp_path / "out")])


def test_out_under_an_existing_file_is_refused_by_every_command(
    tmp_path, capsys, nothing_runs, data_file
):
    a_file = tmp_path / "file"
    a_file.write_text("x")
    for command, base in _bases(data_file).items():
        err = _refused(base, a_file / "sub", capsys)
        assert "is a file, not a folder" in err, (command, err)


def test_seen_cases(tmp_path, capsys, nothing_runs, data_file):
    out = tmp_path / "out"
    sweep = ["sweep", "--scene", "pendulum", "--grid", "length=1,2"]
    assert "--t-end = -1 is invalid" in _refused([*sweep, "--t-end", "-1"], out, capsys)
    err = _refused([*sweep, "--grid", "length=3"], out, capsys)
    assert "--grid length is given twice" in err
    err = _refused(["optimize", "--learning-rate", "-1"], out, capsys)
    assert "--learning-rate = -1 is invalid" in err and "(0, inf)" in err
    err = _refused(["optimize", "--param", "panel1_ra", "--start", "panel1_ra=1e-3"], out, capsys)
    assert "strictly inside the bounds" in err
    err = _refused(["simulate", "deploy_array", "--t-end", "1e6"], out, capsys)
    assert "cannot finish" in err and "steps" in err
    err = _refused(["simulate", "slider_crank", "--t-end", "100"], out, capsys)
    assert "would integrate for about" in err and "--long-run" in err
    err = _refused(["simulate", "pendulum", "--dt", "1e-3", "--dt-max", "1e-2"], out, capsys)
    assert "--dt-max bounds adaptive steps" in err
    err = _refused(
        ["simulate", "pendulum", "--rtol", "1e-6", "--dt", "1", "--dt-max", "0.1"], out, capsys
    )
    assert "--dt = 1 s is invalid" in err


def test_a_long_run_is_accepted_with_the_flag():
    from jaxdeploy.commands.simulate import run_length_problem
    from jaxdeploy.scenes import SliderCrank

    scene = SliderCrank()
    assert run_length_problem(scene, scene.default_control, 100.0, long_run=False) is not None
    assert run_length_problem(scene, scene.default_control, 100.0, long_run=True) is None
    assert run_length_problem(scene, scene.default_control, 0.05, long_run=False) is None


def _readme_commands():
    import pathlib
    import re
    import shlex

    readme = pathlib.Path(__file__).resolve().parents[1] / "README.md"
    commands = []
    for block in re.findall(r"```bash\n(.*?)```", readme.read_text(), flags=re.S):
        for line in block.splitlines():
            line = line.split("#", 1)[0].strip()
            if line.startswith("jaxdeploy "):
                commands.append(shlex.split(line)[1:])
    return commands


def test_every_readme_command_passes_the_checks(tmp_path, monkeypatch, capsys, nothing_runs):
    """The README's command lines are valid as written (names, flags, values): each passes
    every check and reaches its work (here a stand-in), or prints what it lists."""
    commands = _readme_commands()
    assert len(commands) >= 8
    import pathlib
    import shutil

    root = pathlib.Path(__file__).resolve().parents[1]
    monkeypatch.chdir(tmp_path)
    for argv in commands:  # data files the README names, copied beside the outputs
        for arg in argv:
            if arg.startswith("examples/"):
                (tmp_path / "examples").mkdir(exist_ok=True)
                shutil.copy(root / arg, tmp_path / arg)
    for argv in commands:
        try:
            code = main(argv)
        except Compiled:
            continue
        assert code == 0, (argv, capsys.readouterr().err)
