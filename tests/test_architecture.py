"""The package's floors (docs/architecture.md): each module imports only its own floor and the
floors below, and no module imports another unit's private names. Imports inside functions
count too (they are how a cycle hides).

`KNOWN_DEBT` lists the violations that exist today (issue 23, item 1 removes them). The test
fails on a violation not listed — and on a listed one that is gone, so the list only shrinks:
delete its line when you remove the import."""

import ast
import pathlib

import jaxdeploy

PACKAGE = pathlib.Path(jaxdeploy.__file__).parent

# Floor of each top-level unit of the package (docs/architecture.md, "The floors").
FLOORS = {
    "_validation": 0,
    "io": 0,
    "_compilation_cache": 0,
    "contact": 1,
    "mechanism": 2,
    "solvers": 3,
    "simulation": 4,
    "scenes": 5,
    "analysis": 6,
    "batch": 7,
    "lanes": 7,
    "sweep": 7,
    "robustness": 7,
    "fit": 7,
    "objectives": 7,
    "optimize": 7,
    "commands": 8,
    "cli": 8,
}

# "importer -> imported module:name (kind)", modules relative to `jaxdeploy.`; kind "upward"
# (to a higher floor) or "private" (another unit's, or another library's, private name).
KNOWN_DEBT = {
    # scenes ↔ analysis: a scene imports its own analysis (inside methods)
    "scenes.slider_crank -> analysis.slider_crank:slider_crank_summary (upward)",
    "scenes.slider_crank -> analysis.slider_crank:plot_slider_crank (upward)",
    "scenes.deploy_array -> analysis.contact_forces:clearance_joint_history (upward)",
    "scenes.deploy_array -> analysis.deploy_array:deploy_array_summary (upward)",
    "scenes.deploy_array -> analysis.deploy_array:plot_deploy_array (upward)",
    # the batching wing reaches into simulate's internals and a sibling's private helper
    "lanes -> simulation:_setup (private)",
    "lanes -> simulation:_integrate (private)",
    "lanes -> simulation:_saved (private)",
    "lanes -> diffrax._integrate:_clip_to_end (private)",
    "sweep -> batch:_stack_cases (private)",
    "commands.fit -> fit._plots:plot_fit (private)",
    "io -> jaxdeploy:__version__ (upward)",
}


def _unit(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None


def _imports():
    """(importer, imported module, imported name or None) for every import in the package."""
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        is_package = parts[-1] == "__init__"
        module = ".".join(parts[:-1] if is_package else parts)
        package = module if is_package else module.rsplit(".", 1)[0]
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    yield module, alias.name, None
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - node.level + 1]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                for alias in node.names:
                    yield module, target, alias.name


def _describe(importer, target, name, kind):
    def short(module):
        return module.removeprefix("jaxdeploy.")

    return f"{short(importer)} -> {short(target)}:{name} ({kind})"


def _violations():
    found = set()
    for importer, target, name in _imports():
        if importer == "jaxdeploy":
            continue  # the public face re-exports from every floor
        source_unit = _unit(importer)
        if target.split(".")[0] != "jaxdeploy":
            # Another library's private module (e.g. diffrax._integrate) is not its API.
            if any(part.startswith("_") for part in target.split(".")[1:]):
                found.add(_describe(importer, target, name, "private"))
            continue
        target_unit = _unit(target)
        if target_unit is None or FLOORS[target_unit] > FLOORS[source_unit]:
            if not (target_unit is None and name in FLOORS):  # `from .. import contact`
                found.add(_describe(importer, target, name, "upward"))
            elif FLOORS[name] > FLOORS[source_unit]:
                found.add(_describe(importer, target, name, "upward"))
            continue
        if target_unit != source_unit:
            private_module = any(p.startswith("_") for p in target.split(".")[2:])
            private_name = name is not None and name.startswith("_")
            if private_module or private_name:
                found.add(_describe(importer, target, name, "private"))
    return found


def test_every_unit_has_a_floor():
    units = {p.stem if p.is_file() else p.name for p in PACKAGE.iterdir()}
    units = {u for u in units if u not in ("__init__", "__pycache__", "py")}
    units = {u for u in units if (PACKAGE / u).is_dir() or (PACKAGE / f"{u}.py").exists()}
    assert units <= set(FLOORS), f"give these a floor here and in docs: {units - set(FLOORS)}"


def test_imports_go_down_the_floors_and_not_into_private_names():
    found = _violations()
    new = sorted(found - KNOWN_DEBT)
    gone = sorted(KNOWN_DEBT - found)
    assert not new, (
        "imports against docs/architecture.md's floors (or private names):\n" + "\n".join(new)
    )
    assert not gone, "debt paid: delete these lines from KNOWN_DEBT:\n" + "\n".join(gone)
