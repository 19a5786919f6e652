"""Sparse Jacobians by compressed forward-mode differentiation (column colouring).

A mechanism's residual is sparse in its coordinates: an element's constraint rows and forces
depend only on the coordinates of the bodies it touches, and act only on those bodies. Columns
of a Jacobian that share no nonzero row can then be differentiated together: one forward-mode
direction `Σ_{c ∈ group} e_c` returns the sum of their columns, and each row of that sum belongs
to exactly one of them (Curtis, Powell & Reid, *J. Inst. Math. Appl.* 13 (1974) 117; Coleman &
Moré, *SIAM J. Numer. Anal.* 20 (1983) 187). A column whose derivative is zero by structure
needs no direction at all.

For deploy_array this replaces the 21 forward directions of the dense Jacobian of the forces
(where the rough contact law is) by 6: only the two clearance joints' bodies move the forces.

`column_groups(pattern)` colours the columns greedily; `compressed_jacobian(fn, x, pattern)`
evaluates `fn`'s Jacobian with one `jvp` per group and reads the compressed columns back
by a single gather with static indices (entries outside the pattern are exactly 0).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np


def column_groups(pattern: np.ndarray) -> list[list[int]]:
    """Columns of the boolean `pattern` (rows × columns) in groups that share no nonzero row,
    greedily in column order (a distance-2 colouring of the bipartite row–column graph).
    Structurally zero columns are in no group."""
    pattern = np.asarray(pattern, dtype=bool)
    groups: list[list[int]] = []
    rows_of: list[np.ndarray] = []  # rows already occupied by each group
    for c in range(pattern.shape[1]):
        rows = pattern[:, c]
        if not rows.any():
            continue
        for g, occupied in enumerate(rows_of):
            if not (occupied & rows).any():
                groups[g].append(c)
                rows_of[g] = occupied | rows
                break
        else:
            groups.append([c])
            rows_of.append(rows.copy())
    return groups


def compressed_jacobian(fn, x, pattern: np.ndarray):
    """`∂fn/∂x` (rows × len(x)) where it is nonzero only on the static boolean `pattern`.

    One forward-mode direction per group of `column_groups(pattern)`. Entries outside
    `pattern` are returned as exactly 0, whatever `fn` computes there: the caller vouches for
    the pattern.
    """
    pattern = np.asarray(pattern, dtype=bool)
    rows, cols = pattern.shape
    groups = column_groups(pattern)
    if not groups:
        return jnp.zeros((rows, cols), dtype=x.dtype)
    seeds = np.zeros((len(groups), cols))
    colour = np.full(cols, -1)
    for g, members in enumerate(groups):
        seeds[g, members] = 1.0
        colour[members] = g
    _, compressed = jax.vmap(lambda s: jax.jvp(fn, (x,), (s,)))(jnp.asarray(seeds, x.dtype))
    # compressed[g, r] = Σ_{c ∈ group g} J[r, c]; entry (r, c) is compressed[colour(c), r],
    # read by one gather with static indices (a zero appended for entries off the pattern).
    flat = jnp.concatenate([compressed.reshape(-1), jnp.zeros((1,), dtype=compressed.dtype)])
    r_index, c_index = np.indices((rows, cols))
    index = np.where(pattern, colour[c_index] * rows + r_index, flat.shape[0] - 1)
    return flat[index]
