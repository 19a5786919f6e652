"""The package's floors (docs/architecture.md): each module imports only its own floor and the
floors below, and no module imports another unit's private names. Imports inside functions
count too (they are how a cycle hides). Issue 23 item 1 removed the last violations; there is
no list of exceptions."""

import ast
import pathlib

import jaxdeploy

PACKAGE = pathlib.Path(jaxdeploy.__file__).parent

# Floor of each top-level unit of the package (docs/architecture.md, "The floors").
FLOORS = {
    "_validation": 0,
    "_version": 0,
    "io": 0,
    "_output_folder": 0,
    "pages": 0,
    "_compilation_cache": 0,
    "_program_cache": 0,
    "_collector": 0,
    "_read_ahead": 0,
    "_tracing": 0,
    "_xla_flags": 0,
    "_cores": 0,
    "_described": 0,
    "contact": 1,
    "mechanism": 2,
    "solvers": 3,
    "simulation": 4,
    "scenes": 5,
    "analysis": 6,
    "batch": 7,
    "sweep": 7,
    "robustness": 7,
    "fit": 7,
    "objectives": 7,
    "optimize": 7,
    "_design_program": 7,
    "commands": 8,
    "cli": 8,
}


def _unit(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None


def _imports(top_level=None):
    """(importer, imported module, imported name or None) for every import in the package;
    `top_level` True: only the imports run when the module is imported (not inside a
    function), False: only those inside functions."""
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        is_package = parts[-1] == "__init__"
        module = ".".join(parts[:-1] if is_package else parts)
        package = module if is_package else module.rsplit(".", 1)[0]
        tree = ast.parse(path.read_text())
        in_functions = {
            id(node)
            for function in ast.walk(tree)
            if isinstance(function, ast.FunctionDef | ast.AsyncFunctionDef)
            for node in ast.walk(function)
        }
        for node in ast.walk(tree):
            if top_level is not None and (id(node) in in_functions) == top_level:
                continue
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


def _loaded_by(target, name):
    """The package modules an import of `name` from `target` loads: the module and each
    package above it, and `target.name` when that is a submodule."""
    modules = set()
    parts = target.split(".")
    for k in range(1, len(parts) + 1):
        modules.add(".".join(parts[:k]))
    if name is not None:
        modules.add(f"{target}.{name}")
    # The root is loaded first by any import, and its lazy public face loads nothing else.
    return {m for m in modules if m.split(".")[0] == "jaxdeploy" and m != "jaxdeploy"}


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
            dunder = name is not None and name.startswith("__") and name.endswith("__")
            private_name = name is not None and name.startswith("_") and not dunder
            if private_module or private_name:
                found.add(_describe(importer, target, name, "private"))
    return found


def test_every_unit_has_a_floor():
    units = {p.stem if p.is_file() else p.name for p in PACKAGE.iterdir()}
    units = {u for u in units if u not in ("__init__", "__pycache__", "py")}
    units = {u for u in units if (PACKAGE / u).is_dir() or (PACKAGE / f"{u}.py").exists()}
    assert units <= set(FLOORS), f"give these a floor here and in docs: {units - set(FLOORS)}"


def test_imports_go_down_the_floors_and_not_into_private_names():
    # "importer -> imported module:name (kind)", modules relative to `jaxdeploy.`; kind
    # "upward" (to a higher floor) or "private" (another unit's, or another library's, name).
    found = sorted(_violations())
    assert not found, (
        "imports against docs/architecture.md's floors (or private names):\n" + "\n".join(found)
    )


def test_no_import_inside_a_function_hides_a_cycle():
    """An import inside a function is for laziness (start-up time, optional dependencies),
    never to break a cycle: the module it imports must not import the importer back when it
    is loaded."""
    graph = {}
    for importer, target, name in _imports(top_level=True):
        graph.setdefault(importer, set()).update(_loaded_by(target, name))

    def reaches(start, goal):
        seen, todo = set(), [start]
        while todo:
            module = todo.pop()
            if module == goal:
                return True
            if module not in seen:
                seen.add(module)
                todo.extend(graph.get(module, ()))
        return False

    hidden = sorted(
        f"{importer} -> {loaded}"
        for importer, target, name in _imports(top_level=False)
        for loaded in _loaded_by(target, name)
        if loaded != importer
        and not importer.startswith(loaded + ".")  # its own packages are loaded already
        and reaches(loaded, importer)
    )
    assert not hidden, "function-level imports that hide a cycle:\n" + "\n".join(hidden)
