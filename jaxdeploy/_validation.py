"""Input checks that name the parameter, the value and the valid range.

Checks run only on concrete values (Python numbers, numpy arrays, concrete JAX arrays). Inside
`jit`, `vmap` or `grad` the values are tracers and cannot be inspected; they were checked where
the user first supplied them (scene parameters, CLI, file readers), before any compilation.
"""

from __future__ import annotations

import math

import jax
import numpy as np


def is_concrete(value) -> bool:
    """True if `value` holds numbers we can inspect now (no JAX tracer inside)."""
    leaves = jax.tree_util.tree_leaves(value)
    return not any(isinstance(leaf, jax.core.Tracer) for leaf in leaves)


def float_data(value):
    """`value` as float64 data of a compiled program: a NumPy array when it is concrete (a
    Python or NumPy number, or an array already on the host), else `jnp.asarray(value,
    float)`. The program sees the same abstract value either way (float64, not weak), so it
    is the same program; a NumPy array is transferred with the call's other arguments,
    while `jnp.asarray` of a Python float is an operation dispatched on its own (~30 µs on
    the project's 2-core machine: `simulate` made 8 a call, a sixth of a warm 2 µs run)."""
    if isinstance(value, (int, float, np.number, np.ndarray)):
        return _as_numpy(value)
    import jax.numpy as jnp

    return jnp.asarray(value, dtype=float)


def _as_numpy(value) -> np.ndarray:
    return np.asarray(value, dtype=float)


def check_range(
    name: str,
    value,
    low: float = -math.inf,
    high: float = math.inf,
    *,
    low_inclusive: bool = True,
    high_inclusive: bool = True,
    unit: str = "",
):
    """Raise `ValueError` unless every element of `value` is finite and inside the range.

    **Arguments:**
    - `name`: the parameter's name as the user knows it (e.g. `"clearance"`).
    - `value`: scalar or array; skipped silently when it is a JAX tracer.
    - `low`, `high`, `*_inclusive`: the valid range.
    - `unit`: printed after the numbers, e.g. `"m"`.

    **Returns:** `value`, unchanged, so the call can wrap an assignment.
    """
    if not is_concrete(value):
        return value
    arr = _as_numpy(value)
    lo_br = "[" if low_inclusive else "("
    hi_br = "]" if high_inclusive else ")"
    unit_txt = f" {unit}" if unit else ""
    valid = f"{lo_br}{low:g}, {high:g}{hi_br}{unit_txt}"
    bad = ~np.isfinite(arr)
    if low_inclusive:
        bad |= arr < low
    else:
        bad |= arr <= low
    if high_inclusive:
        bad |= arr > high
    else:
        bad |= arr >= high
    if np.any(bad):
        # A Python number, so the message prints 0.00108, not np.float64(0.00108).
        shown = (arr[bad].ravel()[0] if arr.ndim else arr).item()
        raise ValueError(
            f"{name} = {shown!r}{unit_txt} is invalid: it must be finite and in {valid}."
        )
    return value


def check_positive(name: str, value, unit: str = ""):
    """`check_range(name, value, 0, inf, low_inclusive=False)`."""
    return check_range(name, value, 0.0, math.inf, low_inclusive=False, unit=unit)


def check_nonnegative(name: str, value, unit: str = ""):
    """`check_range(name, value, 0, inf)`."""
    return check_range(name, value, 0.0, math.inf, unit=unit)
