"""The planning stage every command shares, between validating its arguments and running:
what the run will need (memory of its outputs), whether its tolerances can mean anything, and
the output folder, locked for it (`jaxdeploy._output_folder`). Each check raises `ValueError`
(a refusal, exit 2) with a message naming the estimate and the limit.

Keep this module light (no JAX at import).
"""

from __future__ import annotations

import os

from ..io import duration_text  # noqa: F401  (the commands' estimates use it from here)

# Bytes of a float64.
FLOAT_BYTES = 8
# Copies of the saved states a run holds at once: the device buffer, its NumPy copy, the
# analysis' histories over the saved states (contact quantities per joint, spectra) and the
# compressed file's buffer. A round upper count: the estimate is for refusing runs that
# cannot fit, not for sizing the machine.
OUTPUT_COPIES = 4
# Share of the memory available that a command may plan to use: the rest is the process
# (JAX, the compiled programs) and whatever else runs on the machine.
MEMORY_SHARE = 0.5


def available_memory() -> int | None:
    """Bytes of memory available to this process: `MemAvailable` of /proc/meminfo, or the
    cgroup's limit less its usage when that is smaller; None when neither can be read."""
    found = []
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    found.append(int(line.split()[1]) * 1024)
    except (OSError, ValueError):
        pass
    try:
        with open("/sys/fs/cgroup/memory.max") as fh:
            limit = fh.read().strip()
        with open("/sys/fs/cgroup/memory.current") as fh:
            used = int(fh.read().strip())
        if limit != "max":
            found.append(int(limit) - used)
    except (OSError, ValueError):
        pass
    return min(found) if found else None


def size_text(n_bytes: float) -> str:
    for unit, size in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n_bytes >= size:
            return f"{n_bytes / size:.3g} {unit}"
    return f"{n_bytes:.0f} B"


def saved_state_bytes(mechanism, n_save: int, runs: int = 1, memory: int | None = None) -> int:
    """Bytes of the saved states of `runs` runs of `mechanism` with `n_save` saved times: q,
    q̇, q̈ (n each), λ (m) and the elements' memory per saved time (`memory` numbers, default
    `memory_floats(mechanism)`), float64, times `OUTPUT_COPIES`."""
    per_state = 3 * mechanism.n_coordinates + mechanism.n_constraints + 1
    per_state += memory_floats(mechanism) if memory is None else int(memory)
    return OUTPUT_COPIES * FLOAT_BYTES * per_state * int(n_save) * int(runs)


def memory_floats(mechanism) -> int:
    """Numbers in the memory of one saved state of `mechanism` (`init_memory`'s shapes;
    traced abstractly, nothing is compiled): an energy meter's memory (`balance_metered`)
    holds several copies of q, more than q itself."""
    import jax
    import numpy as np

    q = jax.ShapeDtypeStruct((mechanism.n_coordinates,), np.float64)
    shapes = jax.eval_shape(mechanism.init_memory, q, q)
    return sum(int(np.prod(leaf.shape)) for leaf in jax.tree.leaves(shapes))


def check_memory(n_bytes: int, what: str, remedy: str) -> None:
    """Refuse (`ValueError`) a plan of `n_bytes` that would not fit in `MEMORY_SHARE` of the
    memory available, naming `what` needs it, the estimate, the limit and the `remedy`."""
    available = available_memory()
    if available is None:
        return
    limit = MEMORY_SHARE * available
    if n_bytes > limit:
        raise ValueError(
            f"{what} would need about {size_text(n_bytes)} of memory, more than the "
            f"{size_text(limit)} a run may use ({MEMORY_SHARE:.0%} of the {size_text(available)} "
            f"available); {remedy}"
        )


def check_tolerances(mechanism, control) -> None:
    """Refuse (`ValueError`) step tolerances too loose to resolve the mechanism's clearances
    (`analysis.plausibility.tolerance_problem`)."""
    from ..analysis.plausibility import tolerance_problem

    problem = tolerance_problem(mechanism, control)
    if problem is not None:
        raise ValueError(problem)


# Runs whose saved states a derivative evaluation holds at once: the run, its tangent or
# cotangent (forward mode's one per parameter counted as one run) and one more beside them (a
# difference run in gradcheck, the ideal reference in optimize, the residuals in fit).
DERIVATIVE_RUNS_HELD = 3


def check_derivative_run(scene, params, control, n_save: int, what: str, remedy: str) -> None:
    """Refuse (`ValueError`) tolerances too loose for the clearances of `scene` at `params`
    (`check_tolerances`) and `n_save` saved states of `DERIVATIVE_RUNS_HELD` runs that would
    not fit in memory (`check_memory`, naming `what` and the `remedy`). Building the mechanism
    compiles nothing: fit, optimize and gradcheck refuse before their first compile."""
    mechanism = scene.build(params)
    check_tolerances(mechanism, control)
    check_memory(saved_state_bytes(mechanism, n_save, runs=DERIVATIVE_RUNS_HELD), what, remedy)


def claim_output(out: str, overwrite: bool):
    """The output folder `out`, locked for this run with a fresh staging folder to write into
    (`_output_folder.OutputFolder`); raises `FileExistsError` with the user's message."""
    from .._output_folder import OutputFolder

    return OutputFolder(out, overwrite).claim()


def shown_path(folder, name: str) -> str:
    """Where file `name` of a committed result is, as the user named the folder."""
    return os.path.join(folder.shown, name)
