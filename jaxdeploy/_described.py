"""A static argument of a cached program, compared by a written-down description.

`_program_cache.call` keys a program by everything its trace depends on; an equinox module's
static fields enter that key through their `repr` (the tree structure's text). An object such
as a scene or a design problem has no exact `repr`, so a program that closes over it cannot be
kept. `Described` carries such an object beside an exact description of everything the trace
reads from it (JSON text, written by its owner: `fit/_model_program.describe`,
`_design_program.runs_spec`, `sweep._describe_chunk`; a scene's part by `scene_record`):
equal descriptions compare and hash equal (one trace per description, in JAX's caches and in
the program cache), and the description is the `repr`.
Without a description (None) the value is compared by identity and printed with its address,
which `_program_cache.key` refuses to keep: such a program is traced in each process.
"""

from __future__ import annotations


class Described:
    """`value` compared, hashed and printed by `description` (module docstring)."""

    __slots__ = ("value", "description", "kind")

    def __init__(self, value, description: str | None, kind: str):
        self.value, self.description, self.kind = value, description, kind

    def __eq__(self, other):
        if not isinstance(other, Described):
            return NotImplemented
        if self.description is None or other.description is None:
            return self is other
        return (self.kind, self.description) == (other.kind, other.description)

    def __hash__(self):
        return hash((self.kind, self.description)) if self.description is not None else id(self)

    def __repr__(self):
        if self.description is None:
            return object.__repr__(self)  # "<... at 0x...>": not kept by the program cache
        return f"{self.kind}({self.description})"


def scene_record(scene, values) -> dict | None:
    """The written-down part a scene contributes to a description: its class and options and
    `values` (parameter values, each a number: concrete numbers choose a scene's
    composition), as `{"scene", "scene_options", "values"}`; None when they cannot be written
    down exactly (a scene class outside jaxdeploy, whose code the program cache's key does
    not hold; a value that is not a number, or is traced)."""
    import numpy as np

    cls = type(scene)
    if not cls.__module__.startswith("jaxdeploy."):
        return None
    try:
        numbers = {k: repr(float(v)) for k, v in values.items() if np.ndim(v) == 0}
    except TypeError:  # a traced value
        return None
    if len(numbers) != len(values):
        return None
    return {
        "scene": f"{cls.__module__}:{cls.__qualname__}",
        "scene_options": scene.options,
        "values": numbers,
    }


def dumps(record) -> str | None:
    """`record` as a description (JSON, keys sorted), or None when JSON cannot hold it."""
    import json

    try:
        return json.dumps(record, sort_keys=True, allow_nan=True)
    except (TypeError, ValueError):
        return None
