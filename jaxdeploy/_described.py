"""A static argument of a cached program, compared by a written-down description.

`_program_cache.call` keys a program by everything its trace depends on; an equinox module's
static fields enter that key through their `repr` (the tree structure's text). An object such
as a scene or a design problem has no exact `repr`, so a program that closes over it cannot be
kept. `Described` carries such an object beside an exact description of everything the trace
reads from it (JSON text, written by its owner: `fit/_model_program.describe`,
`_design_program.describe`): equal descriptions compare and hash equal (one trace per
description, in JAX's caches and in the program cache), and the description is the `repr`.
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
