"""Subcommands of the `jaxdeploy` command line, one module each.

A module here is a subcommand when it defines `NAME` (the word typed), `HELP` (one line),
`add_arguments(parser)` and `run(args) -> int` (the exit code). Modules are found at start-up,
so adding a command means adding a module; keep heavy imports (jax, the solvers) inside `run`
so that `jaxdeploy --help` stays instant. Arguments several commands share (the solver and
step-control group, `--set`, `--scene-option`, output folders) live in `_args.py`.
"""

from __future__ import annotations

import importlib
import pkgutil

# Exit codes of every command (README.md, "Exit codes"); `fit` adds its verdicts 3-5.
EXIT_OK = 0
EXIT_FAILED = 1  # the solver failed (status names when and why), or the run raised
EXIT_REFUSED = 2  # a refused command line: nothing written, nothing compiled
EXIT_IMPLAUSIBLE = 6  # the run finished but failed a plausibility check (status names it)
EXIT_INTERRUPTED = 130  # Ctrl-C (128 + SIGINT, the shell's convention)


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
