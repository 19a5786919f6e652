"""Shared test setup: importing jaxdeploy switches JAX to float64 before any test runs; the
collected tests are ordered longest first for pytest-xdist."""

import json
from pathlib import Path

# The test processes compile many of the same programs (the scenes' default simulations, the
# fits' models) in many files and on both xdist workers. They share JAX's persistent
# compilation cache, in the folder the command line uses (so the in-process tests, the
# command-line tests and the README's commands share it too; `JAXDEPLOY_CACHE_DIR=off` turns
# it off). JAX stores no program with a host callback, and equinox's runtime checks are host
# callbacks unless EQX_ON_ERROR is nan: set before equinox is imported, as the command line
# does (jaxdeploy/_compilation_cache.py); `simulate` checks the same conditions in Python
# first. Only XLA's compile is shared (the key is the compiled program itself); jaxdeploy's
# program store stays off in Python (a monkeypatched setting is not in its key, ae3edd3).
from jaxdeploy._compilation_cache import cache_dir, prefer_cacheable_errors  # noqa: E402

prefer_cacheable_errors()
_SHARED_CACHE = cache_dir()

import jax  # noqa: E402

import jaxdeploy  # noqa: E402, F401  (enables x64)

assert jax.config.jax_enable_x64, "jaxdeploy must enable float64"

if _SHARED_CACHE is not None and not jax.config.jax_compilation_cache_dir:
    from jaxdeploy._compilation_cache import usable_folder

    if usable_folder(_SHARED_CACHE, "compilation cache"):
        jax.config.update("jax_compilation_cache_dir", _SHARED_CACHE)

# Seconds each test took in a full run (`python -m tools.durations RUN.xml` writes it from a
# pytest --junitxml report). Only the order of the run depends on it, never a verdict.
DURATIONS = Path(__file__).with_name("durations.json")


def _recorded_durations() -> dict[str, float]:
    try:
        return json.loads(DURATIONS.read_text())["seconds"]
    except (OSError, ValueError, KeyError):
        return {}


def pytest_collection_modifyitems(config, items):
    """Longest first: `make test` hands tests out one at a time in this order (pytest-xdist
    `--dist load --maxschedchunk 1`), so the long ones start at once and the short ones fill
    the workers' remaining time (longest-processing-time-first scheduling). A test without a
    recorded time counts as long when marked slow, as short otherwise."""
    seconds = _recorded_durations()

    def expected(item) -> float:
        default = 600.0 if item.get_closest_marker("slow") else 0.0
        return seconds.get(item.nodeid, default)

    items.sort(key=expected, reverse=True)
