"""Every command of the README runs as written (issue 22 item 7), so the README cannot rot.

The README's ```bash blocks are parsed line by line (`benchmarks.tour.sections`, which times
the same tour for `make bench`: a trailing backslash continues a line, bash itself drops the
comments) and run with bash in a fresh folder that holds only a link to
`examples/`, with this checkout's code first on the Python path and the environment's `bin`
first on PATH (what `source .venv/bin/activate` does, so that line is not run). `make demo` is
run as its Makefile recipe (the venv is the one running the tests); `make test` and `make
test-fast` are not run: they are the suite this test belongs to (CI runs it).

Strict about what matters, tolerant of run time: every command must exit 0, and each tour
step's "Writes `FOLDER`: `file`, ..." sentence must be true: the command creates one new
folder matching FOLDER (`DATE-TIME` is any stamp) holding every file named. The quick commands
(`jaxdeploy scenes`, `--help`) run in the default suite, the rest under `-m slow`.
"""

import glob
import os
import re
import shlex
import subprocess
import sys

import pytest

from benchmarks.tour import sections

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
README = os.path.join(ROOT, "README.md")
BIN = os.path.dirname(sys.executable)
NOT_RUN = {
    "make test": "the test suite itself (this test is part of it); CI runs it",
    "make test-fast": "the quick test suite, this test included",
    "make test-isa ISA=AVX2": "the whole suite again, compiled for another instruction set",
    "source .venv/bin/activate": "the test puts the environment's bin first on PATH",
}


def _sections():
    """`[(section title, [blocks])]`, each block `(language, [commands], text after it)`."""
    return sections(open(README, encoding="utf-8").read())


def _words(command: str) -> list[str]:
    return shlex.split(command, comments=True)


def _is_quick(command: str) -> bool:
    words = _words(command)
    return words[:2] == ["jaxdeploy", "scenes"] or "--help" in words


def _makefile_recipe(target: str) -> str:
    text = open(os.path.join(ROOT, "Makefile"), encoding="utf-8").read()
    match = re.search(rf"^{target}:.*\n((?:\t.*\n)+)", text, flags=re.M)
    assert match, f"Makefile has no {target!r} target"
    return " && ".join(line.strip().replace("$(BIN)/", "") for line in match.group(1).splitlines())


def _env(cwd):
    env = dict(os.environ)
    env["PATH"] = BIN + os.pathsep + env.get("PATH", "")
    env["PYTHONPATH"] = ROOT + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _workdir(tmp_path):
    os.symlink(os.path.join(ROOT, "examples"), tmp_path / "examples")
    return tmp_path


def _run(command: str, cwd, timeout=3600):
    if _key(command) == "make demo":
        command = _makefile_recipe("demo")
    done = subprocess.run(
        ["bash", "-c", command],
        cwd=cwd,
        env=_env(cwd),
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    assert done.returncode == 0, (
        f"README command `{command}` exited {done.returncode}:\n{done.stdout[-3000:]}\n"
        f"{done.stderr[-3000:]}"
    )
    return done


def _writes(after: str) -> list[tuple[str, list[str]]]:
    """`[(folder pattern, [files])]` of the "Writes `FOLDER`: `f1`, `f2` ..." sentences that
    follow a block (before the next block)."""
    out = []
    for match in re.finditer(r"Writes `([^`]+)`: (.*?)\.(?=\s|$)", after, flags=re.S):
        folder = match.group(1).replace("DATE-TIME", "*").rstrip("/")
        out.append((folder, re.findall(r"`([^`]+)`", match.group(2))))
    return out


def _all_commands():
    return [
        (title, command)
        for title, blocks in _sections()
        for language, commands, _ in blocks
        if language == "bash"
        for command in commands
    ]


def test_readme_has_the_two_commands_and_the_tour():
    keys = [_key(c) for _, c in _all_commands()]
    assert "make demo" in keys and "make test" in keys
    tour = dict(_sections()).get("A five-minute tour")
    assert tour, "README has no '## A five-minute tour' section"
    tour_text = " ".join(" ".join(c) for lang, c, _ in tour if lang == "bash")
    for step in ("simulate", "--set", "sweep", "fit", "optimize"):
        assert step in tour_text, f"the tour has no {step} step"
    assert "examples/slider_crank_slider_x.csv" in tour_text
    for _, commands, after in tour:
        for command in commands:
            if _words(command)[0] == "jaxdeploy" and not _is_quick(command):
                assert _writes(after), f"the tour does not say what `{command}` writes"
                assert re.search(r"\d+ s\b|\d+ min\b", after), (
                    f"the tour does not say how long `{command}` takes"
                )


def _key(command: str) -> str:
    return " ".join(_words(command))


QUICK = [
    pytest.param(c, id=_key(c))
    for c in dict.fromkeys(_key(c) for _, c in _all_commands() if _is_quick(c))
]


@pytest.mark.parametrize("command", QUICK)
def test_quick_readme_command_runs(command, tmp_path):
    done = _run(command, _workdir(tmp_path), timeout=600)
    assert done.stdout.strip(), f"`{command}` printed nothing"


@pytest.mark.slow
def test_the_tour_runs_as_written(tmp_path):
    """The tour in order, in one folder (later steps read what earlier ones wrote)."""
    cwd = _workdir(tmp_path)
    tour = dict(_sections())["A five-minute tour"]
    for language, commands, after in tour:
        for command in commands:
            if _key(command) in NOT_RUN:
                continue
            if language != "bash":
                continue
            before = set(glob.glob(str(cwd / "results" / "**"), recursive=True))
            _run(command, cwd)
            if not commands or command != commands[-1]:
                continue
            for folder, files in _writes(after):
                new = [
                    f for f in glob.glob(str(cwd / folder)) if os.path.isdir(f) and f not in before
                ]
                assert len(new) == 1, f"`{command}`: expected one new {folder}, found {new}"
                for name in files:
                    assert os.path.exists(os.path.join(new[0], name)), (
                        f"`{command}` did not write {name} in {new[0]}"
                    )


OTHER = [
    pytest.param(command, id=_key(command)[:60])
    for title, command in _all_commands()
    if title != "A five-minute tour" and not _is_quick(command)
]


@pytest.mark.slow
@pytest.mark.parametrize("command", OTHER)
def test_readme_command_runs(command, tmp_path):
    if _key(command) in NOT_RUN:
        pytest.skip(NOT_RUN[_key(command)])
    _run(command, _workdir(tmp_path))


@pytest.mark.slow
def test_readme_python_runs(tmp_path):
    for title, blocks in _sections():
        for _, (body,), _ in (b for b in blocks if b[0] == "python"):
            done = subprocess.run(
                [sys.executable, "-c", body],
                cwd=_workdir(tmp_path),
                env=_env(tmp_path),
                capture_output=True,
                text=True,
                timeout=1800,
            )
            assert done.returncode == 0, f"README Python ({title}):\n{done.stderr[-3000:]}"
