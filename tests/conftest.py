"""Shared test setup: importing jaxdeploy switches JAX to float64 before any test runs; the
collected tests are ordered longest first for pytest-xdist."""

import json
from pathlib import Path

import jax

import jaxdeploy  # noqa: F401  (enables x64)

assert jax.config.jax_enable_x64, "jaxdeploy must enable float64"

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
