"""Subcommands of the `jaxdeploy` command line, one module each.

A module here is a subcommand when it defines `NAME` (the word typed), `HELP` (one line),
`add_arguments(parser)` and `run(args) -> int` (the exit code). Modules are found at start-up,
so adding a command means adding a module; keep heavy imports (jax, the solvers) inside `run`
so that `jaxdeploy --help` stays instant.
"""

from __future__ import annotations

import importlib
import pkgutil


def discover() -> list:
    """The command modules, sorted by name."""
    modules = []
    for info in pkgutil.iter_modules(__path__):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        if all(hasattr(module, a) for a in ("NAME", "HELP", "add_arguments", "run")):
            modules.append(module)
    return sorted(modules, key=lambda m: m.NAME)


SOLVER_HELP = "solver by name (default: the scene's; e.g. generalized_alpha, tsit5, kvaerno5)"


def solver_control(scene, name) -> dict:
    """The scene's step control with `--solver NAME` applied; a bad name raises ValueError
    naming the valid ones."""
    from ..solvers import SOLVER_NAMES

    control = dict(scene.default_control)
    if name is not None:
        if name not in SOLVER_NAMES:
            raise ValueError(f"--solver = {name!r} is unknown; valid: {', '.join(SOLVER_NAMES)}")
        control["solver"] = name
    return control


SCENE_OPTION_HELP = (
    "scene option KEY=VALUE (repeatable), e.g. impact_velocity_rule=running_max; "
    "`jaxdeploy simulate SCENE --help` does not list them: see docs/contact.md"
)


def parse_pairs(items, flag: str) -> dict:
    """`KEY=VALUE` items of a repeatable flag; a VALUE that parses as JSON (e.g. `true`,
    `{"J1": "panel1"}`) is decoded, anything else is kept as a string. A malformed or repeated
    KEY raises ValueError naming `flag`."""
    import json

    out = {}
    for item in items:
        if "=" not in item:
            raise ValueError(f"{flag} expects KEY=VALUE, got {item!r}")
        key, value = (s.strip() for s in item.split("=", 1))
        if key in out:
            raise ValueError(f"{flag} {key} is given twice")
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value
    return out
