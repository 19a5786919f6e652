"""Experiments are studies over the public API, not a second package (issue 23 item 5).

Every `experiments/*.py` may import `jaxdeploy`, the names in `jaxdeploy.__all__` and the
public names of its public modules, but nothing private: no module or name of jaxdeploy that
starts with an underscore (if an experiment needs one, the API is missing something).

`KNOWN_DEBT` lists private imports tolerated for now (none today); a violation not listed
fails.

And experiments stay studies, not a second package: their Python lines are at most
`MAX_SHARE` of the lines of `jaxdeploy/`, `tests/` and `experiments/` together. The top-level
`benchmarks/` counts on neither side: it is not experiments, and counting it in the total
would let a growing benchmark suite hide growing experiments."""

import ast
import pathlib

ROOT = pathlib.Path(__file__).resolve().parent.parent
EXPERIMENTS = ROOT / "experiments"
MAX_SHARE = 0.20  # issue 23 item 5

KNOWN_DEBT: set[str] = set()


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def private_imports(source: str) -> list[str]:
    """`module:name` of every import of a private jaxdeploy module or name in `source`
    (imports inside functions count too)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            modules = [(alias.name, None) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            modules = [(node.module, alias.name) for alias in node.names]
        else:
            continue
        for module, name in modules:
            parts = module.split(".")
            if parts[0] != "jaxdeploy":
                continue
            if any(_private(p) for p in parts) or (name is not None and _private(name)):
                found.append(f"{module}:{name}")
    return found


def test_private_imports_are_found():
    source = (
        "import jaxdeploy\nfrom jaxdeploy import simulate, __version__\n"
        "from jaxdeploy.scenes import DeployArray\nimport numpy._core\n"
        "from jaxdeploy.fit._schedule import RTOL_FLOOR\nimport jaxdeploy._validation\n"
        "def f():\n    from jaxdeploy.batch import _stack_cases\n"
    )
    assert private_imports(source) == [
        "jaxdeploy.fit._schedule:RTOL_FLOOR",
        "jaxdeploy._validation:None",
        "jaxdeploy.batch:_stack_cases",
    ]


def test_experiments_use_the_public_api_only():
    found = {
        f"{path.name}: {imp}"
        for path in sorted(EXPERIMENTS.glob("*.py"))
        for imp in private_imports(path.read_text(encoding="utf-8"))
    }
    new = sorted(found - KNOWN_DEBT)
    assert not new, (
        "experiments import private jaxdeploy names (use the public API):\n" + "\n".join(new)
    )


def _python_lines(folder: pathlib.Path) -> int:
    return sum(len(p.read_text(encoding="utf-8").splitlines()) for p in folder.rglob("*.py"))


def test_experiments_are_at_most_a_fifth_of_the_code():
    lines = {name: _python_lines(ROOT / name) for name in ("jaxdeploy", "tests", "experiments")}
    share = lines["experiments"] / sum(lines.values())
    assert share <= MAX_SHARE, (
        f"experiments/ is {share:.1%} of the Python lines ({lines}); move shared logic into "
        "the package and verification into tests/"
    )
