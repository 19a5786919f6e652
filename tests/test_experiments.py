"""Experiments are studies over the public API, not a second package (issue 23 item 5).

Every `experiments/*.py` may import `jaxdeploy`, the names in `jaxdeploy.__all__` and the
public names of its public modules, but nothing private: no module or name of jaxdeploy that
starts with an underscore (if an experiment needs one, the API is missing something).

`KNOWN_DEBT` lists the private imports that exist today in scripts other owners are moving
(out to `benchmarks/`, or into the package); delete a line when its import is gone. A
violation not listed fails."""

import ast
import pathlib

ROOT = pathlib.Path(__file__).resolve().parent.parent
EXPERIMENTS = ROOT / "experiments"

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
