"""Shared test setup: importing jaxdeploy switches JAX to float64 before any test runs; the
collected tests are ordered longest first for pytest-xdist."""

import ctypes
import gc
import json
import os
from pathlib import Path

import pytest

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


# Each pytest-xdist worker is one process that runs about half the suite (~490 tests), and JAX
# keeps every program it compiled alive while the function that owns it lives: the scenes'
# programs are module-level (`eqx.filter_jit`, functools.cache), so a worker only grows.
# Measured on a clean checkout (`make test`, 2 workers, fresh caches): the workers peaked at
# 9.1 and 6.4 GB resident; tests/test_loop.py alone takes one process from 0.5 to 2.3 GB, and
# jax.clear_caches() with malloc_trim brings it back to 0.51 GB. In CI a worker died mid-run
# on a 24 GiB host ("node down: Not properly terminated", no Python traceback), most likely
# the kernel's out-of-memory kill. So a worker that has grown past WORKER_MEMORY drops JAX's
# caches after its test: later tests trace again and take XLA's compile from the persistent
# cache above. No verdict depends on it.
WORKER_MEMORY = 4 * 2**30  # bytes: two workers, each with room for one large test beside it


def resident_bytes() -> int:
    """This process's resident memory (Linux /proc; 0 where there is none)."""
    try:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0


def release_memory() -> None:
    """Drop JAX's compiled programs and hand freed heap back to the system (glibc's malloc
    keeps it otherwise: 2.26 GB resident after clear_caches, 0.51 GB after the trim)."""
    jax.clear_caches()
    gc.collect()
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc: the freed memory is reused, not returned
        pass


@pytest.fixture(autouse=True)
def _bounded_worker_memory():
    yield
    if resident_bytes() > WORKER_MEMORY:
        release_memory()
