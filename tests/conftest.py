"""Shared test setup: importing jaxdeploy switches JAX to float64 before any test runs."""

import jax

import jaxdeploy  # noqa: F401  (enables x64)

assert jax.config.jax_enable_x64, "jaxdeploy must enable float64"


def pytest_collection_modifyitems(config, items):
    """Tests marked slow run first (stable order otherwise): `make test-all` hands tests out
    one at a time in this order (pytest-xdist `--dist load --maxschedchunk 1`), so the long
    ones start at once and the short ones fill the workers' remaining time."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)
