"""How many cores this process may run on: the sweep's threads (`sweep`'s policy `each`) and
the command line's JAX CPU devices (`commands/_devices`) count the same cores."""

from __future__ import annotations

import os


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where the system has one)."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return os.cpu_count() or 1
