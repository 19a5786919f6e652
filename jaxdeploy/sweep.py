"""Parameter sweeps at scale: vmapped chunks, sharded across devices, written as they finish,
resumable after a crash.

The cases are the Cartesian product of the grid, in a fixed order (the last name varies
fastest); case `i` is always the same parameter set. They run in chunks of `chunk_size` cases:
each chunk is one compiled batch (`batch.batch_function`, compiled once for the sweep) whose
batch axis is sharded over all local devices (a `NamedSharding` over a 1-D mesh of
`jax.devices()`; the chunk is padded to a multiple of the device count with copies of its last
case, dropped on output), so memory is bounded by one chunk, whatever the number of cases.
Each device batches its shard by the sweep's `policy` (one vmap of its shard, or vmapped
groups), or, with the policy `each`, each case runs alone, as `simulate` runs it, two at a
time on a machine of two cores (`parse_policy`; `auto`, the default, takes `each` for a sweep
of at most `AUTO_EACH_CASES_PER_CORE` cases per core).

Each finished chunk is written atomically as `chunk_NNNNN.npz` (case indices, parameters,
status, step counts, optional per-case features, summaries and trajectories), then recorded in
`manifest.json` (also written atomically). A chunk counts as done only once it is in the
manifest and its file exists, so a kill at any moment loses at most the running chunk; `resume`
re-runs exactly the chunks not yet recorded: no case is lost or duplicated. The manifest stores
the sweep's definition (scene, grid, fixed parameters, times, step control, chunk size,
policy, versions); resuming with a different definition is refused.

Multi-host (`jax.distributed`): start the same command on every host after
`jax.distributed.initialize()` (the `--distributed` flag calls it, reading the coordinator
address, process count and id from the usual `JAX_COORDINATOR_ADDRESS`, `JAX_NUM_PROCESSES`,
`JAX_PROCESS_ID` environment variables or the cluster's auto-detection). `jax.devices()` is then
the global device list, each chunk is one program over all hosts' devices (inputs built with
`jax.make_array_from_callback`, so each host supplies only its shards), results are gathered
with `multihost_utils.process_allgather`, and only process 0 writes files (and holds the output
folder's lock, `jaxdeploy sweep`).
"""

from __future__ import annotations

import itertools
import math
import os
import sys
import time
from collections.abc import Callable, Mapping
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._cores import usable_cores
from ._described import Described, dumps, scene_record
from ._validation import check_positive
from .batch import batch_function, stack_cases, step_control
from .io import (
    atomic_write_json,
    atomic_write_npz,
    check_output_dir,
    duration_text,
    run_metadata,
    strict_json,
)
from .scenes.base import Scene
from .simulation import result_code
from .solvers.step_control import StepControl

MANIFEST = "manifest.json"
# How each chunk is batched (`parse_policy`): `auto`, which takes `each` (every case alone)
# for a sweep of at most `AUTO_EACH_CASES_PER_CORE` cases per usable core and `all` (one vmap
# of each device's shard) for a larger one. (Lanes refilled from the pending cases, the
# default before, cost more per simulation than a plain vmap on slider_crank and were removed.)
DEFAULT_POLICY = "auto"
DEFAULT_CHUNK_SIZE = 64
# Why `each` for a few cases: a vmapped program is another compile than the single run of
# `jaxdeploy simulate` and `jaxdeploy.simulate` (slider_crank: 13.5 s against 8.4 s,
# docs/performance.md), which cases run alone reuse (its programs kept in the program cache),
# running as threads on every core. Why only a few: small dense linear algebra costs per
# operation, so a vmap's lanes share most of a step's cost, and each case alone pays its own
# dispatch (scene build, assembly and the run's arguments in Python). The vmapped chunk's
# program is kept in the program cache too (`_chunk_program`). Measured on 2 cores (Xeon,
# AVX-512), whole processes, with empty caches and then the caches the first filled
# (`jaxdeploy sweep`, deploy_array to 0.6 s over spring stiffness; slider_crank after two
# `jaxdeploy simulate` runs of it, as the README's tour runs it):
#   slider_crank, 3 cases   each 7.5 s                   vmapped on 2 devices 12.5 s
#   deploy_array, 4 cases   each 42.5 s, again 15.3 s    vmapped 40.8 s, again 9.7 s
#   deploy_array, 16 cases  each 82.4 s, again 46.7 s    vmapped 51.6 s, again 16.6 s
# (So for deploy_array the vmap is now the faster at 4 cases too; `auto` still runs them one
# by one: the threshold counts cases, not what a case costs.)
AUTO_EACH_CASES_PER_CORE = 2


def parse_policy(text: str) -> dict:
    """A batch policy, as the manifest records it: `"all"` (one vmap of the chunk),
    `"groups:G"` (vmapped groups of G one after another), `"each"` (every case alone, as
    `simulate` runs it: `_each_function`) or `"auto"` (`resolve_policy`: resolved before it
    is recorded). Anything else is refused, naming the valid forms."""
    parts = str(text).strip().split(":")
    try:
        numbers = [int(p) for p in parts[1:]]
    except ValueError:
        numbers = None
    kind = parts[0]
    valid = numbers is not None and all(n >= 1 for n in numbers)
    if kind in ("all", "each", "auto") and valid and not numbers:
        return {"kind": kind}
    if kind == "groups" and valid and len(numbers) == 1:
        return {"kind": "groups", "group_size": numbers[0]}
    raise ValueError(
        f"policy = {text!r} is invalid; valid: 'auto', 'each', 'all' or 'groups:G' with an "
        "integer G ≥ 1"
    )


def resolve_policy(
    policy: dict, n_cases: int, process_count: int = 1, cores: int | None = None
) -> dict:
    """The policy a sweep of `n_cases` runs by: `auto` is `each` up to
    `AUTO_EACH_CASES_PER_CORE` cases per core (`cores`, default the usable cores of this
    process; the reason is beside the constant), else `all`; and `all` in a sweep of several
    processes (`jax.distributed`), whose chunks are one program over every host's devices.
    `each` is refused there: every process would run every case."""
    if policy["kind"] == "each" and process_count > 1:
        raise ValueError(
            "policy = 'each' runs every case in every process of a distributed sweep; use "
            "'all' or 'groups:G'"
        )
    if policy["kind"] != "auto":
        return policy
    cores = usable_cores() if cores is None else cores
    if process_count == 1 and n_cases <= AUTO_EACH_CASES_PER_CORE * cores:
        return {"kind": "each"}
    return {"kind": "all"}


def _policy_options(policy: dict) -> dict:
    """`batch_function` keywords of a parsed policy."""
    if policy["kind"] == "groups":
        return {"group_size": policy["group_size"]}
    return {}


def _each_function(
    scene: Scene,
    varied: tuple[str, ...],
    shared: Mapping,
    t_end: float,
    ts,
    *,
    control: StepControl,
    evaluate: Callable,
    sharding=None,
    energy_meter: bool = False,
):
    """The policy `each`'s counterpart of `batch.batch_function` (same call and results):
    `run(values, t_end=t, ts=times)` runs every case of `values` (a `(B,)` array per varied
    name) alone, as `batch.run_scene` runs it with the case's parameters as numbers (the
    scene built for them, its initial state and its run through the program cache: the
    programs `jaxdeploy simulate` and `jaxdeploy.simulate` run and keep), and returns
    `(trajectories, features)` stacked along a leading case axis, as the vmap returns them;
    `evaluate(params, trajectory)` is one compiled program for every case, the varied
    parameters its data. The first case runs alone (it traces, compiles or reads the
    programs); the others as many at a time as the process may use cores (XLA runs calls of
    one device side by side, each on its calling thread). A case that repeats the one before
    it (a chunk's padding) is not run again. `sharding` is not used: the cases are not
    placed, and run on the default device."""
    import concurrent.futures
    import warnings

    import equinox as eqx

    from .batch import run_scene
    from .mechanism import balance_metered, without_balance_meter

    features = eqx.filter_jit(evaluate)
    default_t_end, default_ts = float(t_end), np.asarray(ts, dtype=float)

    def case(values, horizon, times):
        named = dict(zip(varied, values, strict=True))
        params = {**shared, **{k: float(v) for k, v in named.items()}}
        trajectory = run_scene(
            scene, params, horizon, ts=times, control=control, energy_meter=energy_meter
        )
        plain = trajectory
        if energy_meter and balance_metered(scene.build(params)) is not None:
            plain = without_balance_meter(trajectory)
        # The varied parameters as data, so that one program serves every case.
        data = {**shared, **{k: jnp.asarray(float(v)) for k, v in named.items()}}
        return jax.tree.map(np.asarray, (trajectory, features(data, plain)))

    def run(values, t_end=default_t_end, ts=default_ts):
        rows = list(zip(*(np.asarray(v, dtype=float) for v in values), strict=True))
        distinct = [i for i, row in enumerate(rows) if i == 0 or row != rows[i - 1]]
        horizon, times = float(t_end), jnp.asarray(ts, dtype=float)
        results = {distinct[0]: case(rows[distinct[0]], horizon, times)}
        # Each thread's run enters `warnings.catch_warnings` (`run_scene`), which is not
        # thread-safe: whatever they leave of the warning filters is undone here.
        with (
            warnings.catch_warnings(),
            concurrent.futures.ThreadPoolExecutor(usable_cores()) as pool,
        ):
            rest = {i: pool.submit(case, rows[i], horizon, times) for i in distinct[1:]}
            try:
                results.update({i: future.result() for i, future in rest.items()})
            except BaseException:  # an error or Ctrl-C: the cases not begun are not run
                pool.shutdown(cancel_futures=True)
                raise
        ran = [results[max(d for d in distinct if d <= i)] for i in range(len(rows))]
        try:
            return jax.tree.map(lambda *leaves: np.stack(leaves), *ran)
        except ValueError as err:  # the cases' trajectories differ in structure
            raise ValueError(
                f"the cases of this sweep run mechanisms of different compositions ({err}), "
                "which policy 'each' cannot stack; use policy 'all'"
            ) from None

    return run


class _ChunkSpec(eqx.Module):
    """What a sweep's chunk program runs (`_describe_chunk`), as the static part of its
    arguments (`_chunk_program`)."""

    static: Described = eqx.field(static=True)


def _describe_chunk(scene, varied, shared, control, sharding, options) -> str | None:
    """The description that keys a chunk's program (`_kept_batch_function`): the scene's
    class and options, the varied parameters' names, every other parameter's value
    (concrete numbers choose a scene's composition), the step control, the devices the
    chunk is split over and `batch_function`'s other options; None when it cannot be
    written down exactly (a scene class outside jaxdeploy, a value that is not a number,
    several processes)."""
    record = scene_record(scene, shared)
    if jax.process_count() > 1 or record is None:
        return None
    return dumps({
        **record,
        "varied": list(varied),
        "control": repr(control),
        "devices": None if sharding is None else int(sharding.mesh.devices.size),
        "options": {k: repr(v) for k, v in sorted(options.items())},
    })  # fmt: skip


@eqx.filter_jit
def _chunk_program(spec: _ChunkSpec, values, horizon, times):
    """`batch.batch_function`'s program of the chunk `spec` describes, without features, as a
    module-level function the program cache keeps (`_kept_batch_function`)."""
    scene, varied, shared, control, sharding, options = spec.static.value
    run = batch_function(scene, varied, shared, horizon, times, control=control,
                         evaluate=_wrap(None), sharding=sharding, **options)  # fmt: skip
    return run(values, horizon, times)


def _kept_batch_function(
    scene, varied, shared, t_end, ts, *, control, evaluate, sharding, **options
):
    """`batch.batch_function` (the same call and results) whose program the program cache
    keeps, so that a second sweep process of the same definition traces nothing: its program
    is `_chunk_program`, keyed by `_describe_chunk`. Only for a sweep without features
    (`evaluate` None: a function cannot be written down) and with the program cache on;
    otherwise `batch_function` itself, traced in each process. The chunk's values are passed
    as host arrays: the kept program lays them out over the devices it was made for."""
    from . import _program_cache

    description = None
    if evaluate is None and _program_cache.folder() is not None:
        description = _describe_chunk(scene, varied, shared, control, sharding, options)
    if description is None:
        return batch_function(scene, varied, shared, t_end, ts, control=control,
                              evaluate=_wrap(evaluate), sharding=sharding, **options)  # fmt: skip
    value = (scene, tuple(varied), dict(shared), control, sharding, dict(options))
    spec = _ChunkSpec(Described(value, description, "SweepChunk"))
    default_t_end, default_ts = float(t_end), np.asarray(ts, dtype=float)

    def run(values, t_end=default_t_end, ts=default_ts):
        values = tuple(np.asarray(v, dtype=float) for v in values)
        horizon, times = np.asarray(t_end, dtype=float), np.asarray(ts, dtype=float)
        return _program_cache.call(_chunk_program, spec, values, horizon, times)

    return run


def chunk_shape(chunk_size: int, n_cases: int, n_devices: int) -> int:
    """Cases per compiled chunk: `chunk_size` rounded up to a multiple of the device count, but
    no more than the sweep needs, rounded up to a power of two per device. A small sweep then
    runs a few padded copies instead of a full chunk of them (3 cases: 4 slots, not 64), and
    chunk shapes come from a short list (powers of two), so the compiled program of one shape
    serves every later sweep of the scene that needs it (persistent compilation cache)."""
    per_device = math.ceil(chunk_size / n_devices)
    needed = 2 ** math.ceil(math.log2(max(math.ceil(n_cases / n_devices), 1)))
    return n_devices * min(per_device, needed)


def grid_cases(grid: Mapping[str, list]) -> dict[str, np.ndarray]:
    """The Cartesian product of `grid` `{name: values}` as `{name: (B,) array}`, the last name
    varying fastest."""
    if not grid:
        raise ValueError("grid: give at least one NAME=v1,v2,...")
    for name, values in grid.items():
        if len(values) == 0:
            raise ValueError(f"grid: {name!r} has no values")
    rows = list(itertools.product(*grid.values()))
    return {name: np.array([float(r[i]) for r in rows]) for i, name in enumerate(grid)}


def _definition(scene, grid, fixed, t_end, n_save, control, chunk_size, features, policy) -> dict:
    return {
        "scene": scene.name,
        "grid": {k: [float(v) for v in vs] for k, vs in grid.items()},
        "fixed": {k: float(v) for k, v in (fixed or {}).items()},
        "t_end": float(t_end),
        "n_save": int(n_save),
        "control": control.to_json(),
        "chunk_size": int(chunk_size),
        "features": features,
        # The policy can change a case's round-off and so its steps.
        "policy": policy,
    }


def _read_manifest(path):
    import json

    with open(path) as fh:
        return json.load(fh)


def _device_mesh():
    from jax.sharding import Mesh, NamedSharding, PartitionSpec

    devices = np.array(jax.devices())
    mesh = Mesh(devices, ("cases",))
    return NamedSharding(mesh, PartitionSpec("cases")), len(devices)


def _place(values: np.ndarray, sharding):
    """A global array sharded over the mesh, each process supplying its own shards."""
    return jax.make_array_from_callback(values.shape, sharding, lambda index: values[index])


def _gather(tree):
    if jax.process_count() > 1:
        from jax.experimental import multihost_utils

        return multihost_utils.process_allgather(tree, tiled=True)
    return jax.tree.map(np.asarray, tree)


def sweep(
    scene: Scene,
    grid: Mapping[str, list],
    out_dir: str,
    *,
    t_end: float | None = None,
    n_save: int = 201,
    fixed: Mapping | None = None,
    control: StepControl | Mapping | None = None,
    chunk_size: int = DEFAULT_CHUNK_SIZE,
    policy: str = DEFAULT_POLICY,
    resume: bool = False,
    evaluate: Callable | None = None,
    features: str | None = None,
    summarize: Callable | None = None,
    save_trajectories: bool = True,
    progress: bool = False,
    stop_after_chunks: int | None = None,
    seed: int | None = None,
    energy_meter: bool = False,
    probe: Callable | None = None,
) -> dict:
    """Run every case of `grid` (Cartesian product; see module docstring) into `out_dir`.

    **Arguments:**
    - `grid`: `{name: [values]}`; `fixed`: other parameters (defaults otherwise).
    - `control`: a `StepControl` for every case (or a mapping of its fields overriding the
      scene's default); recorded in the manifest's definition.
    - `chunk_size`: cases per compiled run (bounds memory; rounded up to a multiple of the
      device count, and down to what the sweep needs: `chunk_shape`).
    - `policy`: how a chunk's cases run (`parse_policy`): `"each"` (every case alone, as
      `simulate` runs it, as many at a time as the process may use cores; its programs are
      the single run's, kept in the program cache), `"all"` (one vmap of each device's shard)
      or `"groups:G"`; `"auto"` (default `DEFAULT_POLICY`) takes `"each"` for at most
      `AUTO_EACH_CASES_PER_CORE` cases per usable core, else `"all"` (resumed: as the sweep
      was started).
      Recorded in the definition, resolved: it can change a case's round-off and hence its
      steps.
    - `resume`: continue a sweep in `out_dir` (its definition must match); without it a
      non-empty `out_dir` is refused.
    - `evaluate(params, trajectory) -> {name: scalar}`: per-case features computed inside the
      compiled run (e.g. design objectives); `features` names it in the manifest.
    - `summarize(params, trajectory) -> {name: value}`: per-case quantities computed on the
      host after each chunk, from the case's own (unbatched) trajectory and its parameters as
      Python floats (e.g. the scene's summary, which is NumPy post-processing and so cannot
      run inside the compiled program); stored per case as strict JSON (`summary` in the
      chunk file, `null` for NaN). Whether a sweep summarizes is part of its definition.
    - `save_trajectories`: store `q`, `v` at the saved times per case.
    - `stop_after_chunks`: stop (raise `KeyboardInterrupt`) after that many chunks of this call
      (tests of resume).
    - `energy_meter`: run every case with its energy meter where its mechanism allows one
      (`batch.run_scene`; no step changes): the trajectory `summarize` gets then ends its
      memory with the meter's, for the case's energy balance (`mechanism.metered_balance`).
    - `probe(run_to, chunks, cases)`: called once before the first chunk runs, with
      `run_to(t) -> (steps, ok, case)`, which runs the first chunk still to do over [0, t]
      with the sweep's compiled program (the end time is data: nothing compiles twice) and
      returns the most steps (accepted and rejected) any of its cases took, whether any
      finished, and its first case as `(params, trajectory)` (what `summarize` gets), and
      the number of chunks and cases still to do. It may time the prefixes and refuse the
      sweep by raising (`jaxdeploy sweep` estimates the sweep's time with it); nothing has
      been written yet.

    **Returns:** the manifest (a dict).

    Stages: `_setup` (every argument and case checked, the definition) → `_open_manifest`
    (resume or new) → `_chunks_to_run` → per chunk `_run_chunk` → `_store_chunk`.
    """
    if resume and parse_policy(policy)["kind"] == "auto":
        policy = _recorded_policy(out_dir) or policy  # as the sweep was started
    setup = _setup(scene, grid, t_end, n_save, fixed, control, chunk_size, policy, features)
    setup.definition["summary"] = summarize is not None
    manifest = _open_manifest(out_dir, setup, resume, seed)
    todo = _chunks_to_run(out_dir, manifest, setup)
    each = setup.policy["kind"] == "each"
    runner = _each_function if each else _kept_batch_function
    run = runner(
        scene,
        setup.varied,
        setup.shared,
        setup.t_end,
        setup.ts,
        control=setup.control,
        evaluate=_wrap(evaluate) if each else evaluate,
        sharding=setup.sharding,
        energy_meter=energy_meter,
        **_policy_options(setup.policy),
    )
    if probe is not None and todo:
        cases = sum(_chunk_range(setup, k)[1] - _chunk_range(setup, k)[0] for k in todo)
        probe(_prefix_runner(run, setup, todo[0]), len(todo), cases)
    bar = _progress(
        progress, setup.n_cases, sum(c["stop"] - c["start"] for c in manifest["chunks"])
    )
    for count, k in enumerate(todo):
        if stop_after_chunks is not None and count >= stop_after_chunks:
            raise KeyboardInterrupt(f"sweep stopped after {count} chunks (stop_after_chunks)")
        record, arrays = _run_chunk(run, setup, k, summarize, save_trajectories)
        _store_chunk(out_dir, manifest, record, arrays)
        if bar is not None:
            bar.update(record["stop"] - record["start"])
    if bar is not None:
        bar.close()
    return manifest


class _Setup(NamedTuple):
    """A sweep's checked settings: its end time, saved times `ts`, step control, parsed
    policy, number of cases, the cases' parameter `table` split into `varied` names and
    `shared` values, the devices' `sharding`, the chunk size and the `definition` (what
    --resume compares)."""

    t_end: float
    ts: jax.Array
    control: StepControl
    policy: dict
    n_cases: int
    table: dict
    varied: tuple
    shared: dict
    sharding: object
    chunk_size: int
    definition: dict


def _setup(scene, grid, t_end, n_save, fixed, control, chunk_size, policy, features) -> _Setup:
    """Validate the sweep's arguments and every case (names, ranges) before anything runs;
    a bad one raises `ValueError` naming it."""
    t_end = scene.default_t_end if t_end is None else float(t_end)
    check_positive("t_end", t_end, "s")
    if not (isinstance(n_save, int) and not isinstance(n_save, bool) and n_save >= 2):
        raise ValueError(f"n_save = {n_save!r} is invalid: it must be an integer ≥ 2")
    control = step_control(scene, control)
    if not (isinstance(chunk_size, int) and chunk_size >= 1):
        raise ValueError(f"chunk_size = {chunk_size!r} is invalid: it must be an integer ≥ 1")
    cases = grid_cases(grid)
    n_cases = len(next(iter(cases.values())))
    parsed = policy if isinstance(policy, dict) else parse_policy(policy)  # dict: recorded
    parsed_policy = resolve_policy(parsed, n_cases, jax.process_count())
    table, varied, shared = stack_cases(scene, cases, fixed)
    if not varied:  # one case (or copies): still trace the first grid name
        first = next(iter(grid))
        varied, shared = (first,), {k: v for k, v in shared.items() if k != first}
    if parsed_policy["kind"] == "each":  # cases alone, on the default device: not placed
        sharding, n_devices = None, 1
    else:
        sharding, n_devices = _device_mesh()
    chunk_size = chunk_shape(chunk_size, n_cases, n_devices)
    definition = _definition(
        scene, grid, fixed, t_end, n_save, control, chunk_size, features, parsed_policy
    )
    return _Setup(
        t_end=t_end,
        ts=jnp.linspace(0.0, t_end, n_save),
        control=control,
        policy=parsed_policy,
        n_cases=n_cases,
        table=table,
        varied=tuple(varied),
        shared=shared,
        sharding=sharding,
        chunk_size=chunk_size,
        definition=definition,
    )


def _recorded_policy(out_dir: str) -> dict | None:
    """The policy the sweep in `out_dir` was started with (`all` for one written before
    policies were recorded), or None when there is none to read (the refusal, if any, is
    `_open_manifest`'s)."""
    try:
        definition = _read_manifest(os.path.join(out_dir, MANIFEST))["definition"]
        policy = definition.get("policy", {"kind": "all"})
        return policy if policy.get("kind") in ("all", "each", "groups") else None
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None


def _open_manifest(out_dir: str, setup: _Setup, resume: bool, seed) -> dict:
    """The manifest of the sweep in `out_dir`: the one there (with `resume`, when it was
    defined as `setup` is; else refused), or a new one (for an empty or missing folder;
    written with the first finished chunk)."""
    manifest_path = os.path.join(out_dir, MANIFEST)
    if os.path.exists(manifest_path):
        if not resume:
            raise FileExistsError(
                f"{out_dir!r} already holds a sweep; pass --resume to continue it or choose "
                "another --out"
            )
        manifest = _read_manifest(manifest_path)
        # Sweeps written before the policy was recorded ran each chunk as one vmap.
        manifest["definition"].setdefault("policy", {"kind": "all"})
        # ... and those written before per-case summaries were stored had none.
        manifest["definition"].setdefault("summary", False)
        if manifest["definition"] != setup.definition:
            raise ValueError(
                f"--resume: the sweep in {out_dir!r} was defined differently: "
                + "; ".join(_differences(manifest["definition"], setup.definition))
                + "; resume it with the same settings, or start a new sweep in another --out"
            )
        return manifest
    if os.path.isdir(out_dir) and os.listdir(out_dir):
        raise FileExistsError(
            f"output folder {out_dir!r} is not empty and holds no sweep manifest; choose "
            "another --out"
        )
    check_output_dir(out_dir, overwrite=False)  # a file in the way, a read-only folder
    # Written with the first finished chunk, not now: a sweep that fails before finishing
    # one (a case the scene cannot assemble, an interrupt while compiling) leaves no
    # manifest behind to block the corrected rerun.
    return {
        "definition": setup.definition,
        "n_cases": setup.n_cases,
        "varied": list(setup.varied),
        "params": {k: float(v) for k, v in setup.shared.items()},
        "seed": seed,
        "devices": [str(d) for d in jax.devices()],
        "process_count": jax.process_count(),
        "versions": run_metadata(),
        "chunks": [],
    }


def _chunks_to_run(out_dir: str, manifest: dict, setup: _Setup) -> list[int]:
    """The chunks not yet done (recorded in the manifest with their file present); the
    manifest keeps only the done ones."""
    done = {c["index"] for c in manifest["chunks"] if _chunk_done(out_dir, c)}
    manifest["chunks"] = [c for c in manifest["chunks"] if c["index"] in done]
    n_chunks = math.ceil(setup.n_cases / setup.chunk_size)
    return [k for k in range(n_chunks) if k not in done]


def _chunk_range(setup: _Setup, k: int) -> tuple[int, int]:
    """`(start, stop)`: the cases of chunk `k`."""
    return k * setup.chunk_size, min((k + 1) * setup.chunk_size, setup.n_cases)


def _chunk_inputs(setup: _Setup, k: int):
    """The varied parameters of chunk `k`'s cases, padded to the chunk size with copies of
    its last case, placed on the devices."""
    start, stop = _chunk_range(setup, k)
    index = np.arange(start, stop)
    padded = np.concatenate([index, np.full(setup.chunk_size - len(index), stop - 1)])
    if setup.sharding is None:  # `each`: the values themselves
        return tuple(setup.table[name][padded] for name in setup.varied)
    return tuple(_place(setup.table[name][padded], setup.sharding) for name in setup.varied)


def _prefix_runner(run, setup: _Setup, k: int):
    """`run_to(t) -> (steps, ok)`: chunk `k` over [0, t] (`sweep`'s `probe`), saving as many
    states as the sweep does (the same program), over [0, t]."""
    inputs = _chunk_inputs(setup, k)
    n_save = int(setup.ts.shape[0])

    def run_to(t: float) -> tuple[int, bool, tuple]:
        trajectory, _ = run(inputs, t_end=t, ts=jnp.linspace(0.0, t, n_save))
        trajectory = _gather(trajectory)
        result, steps = result_code(trajectory.result), trajectory.stats["num_steps"]
        # The chunk's first case as `summarize` gets it (its host work is part of a case's
        # cost too).
        first = int(_chunk_range(setup, k)[0])
        case = (
            {name: float(setup.table[name][first]) for name in setup.table},
            jax.tree.map(lambda leaf: leaf[0], trajectory),
        )
        # A vmapped loop steps until its slowest case is done: the chunk's cost is its most
        # steps. A failed case stops early; the others go on.
        return int(np.max(steps)), bool(np.any(result == 0)), case

    return run_to


def _run_chunk(run, setup: _Setup, k: int, summarize, save_trajectories: bool):
    """Run chunk `k` (padded to the chunk size with copies of its last case); **returns**
    its manifest record and the arrays of its file."""
    table = setup.table
    start, stop = _chunk_range(setup, k)
    index = np.arange(start, stop)
    began = time.perf_counter()
    inputs = _chunk_inputs(setup, k)
    trajectory, feats = run(inputs)
    trajectory, feats = _gather((trajectory, feats))
    n = len(index)
    arrays = {
        "case": index,
        "result": result_code(trajectory.result)[:n],
        "num_steps": np.asarray(trajectory.stats["num_accepted_steps"])[:n],
        "num_rejected": np.asarray(trajectory.stats["num_rejected_steps"])[:n],
        **{f"param_{name}": table[name][index] for name in table},
        **{f"feature_{name}": np.asarray(v)[:n] for name, v in feats.items()},
    }
    if summarize is not None:
        arrays["summary"] = np.array(
            [
                strict_json(
                    summarize(
                        {name: float(table[name][i]) for name in table},
                        jax.tree.map(lambda leaf, j=j: leaf[j], trajectory),
                    )
                )
                for j, i in enumerate(index)
            ]
        )
    if save_trajectories:
        arrays.update(t=np.asarray(setup.ts), q=trajectory.q[:n], v=trajectory.v[:n])
    record = {
        "index": k,
        "file": f"chunk_{k:05d}.npz",
        "start": int(start),
        "stop": int(stop),
        "failed": int(np.sum(arrays["result"] != 0)),
        "wall_time_s": time.perf_counter() - began,
    }
    return record, arrays


def _store_chunk(out_dir: str, manifest: dict, record: dict, arrays: dict) -> None:
    """Write a finished chunk's file, then record it in the manifest (both atomically: a
    chunk counts as done only once both are there). Every process keeps the same manifest
    (so each returns the same account of the sweep); only process 0 writes."""
    writer = jax.process_index() == 0
    manifest_path = os.path.join(out_dir, MANIFEST)
    if writer and not os.path.exists(manifest_path):  # first chunk: define the sweep first
        atomic_write_json(manifest_path, manifest)
    if writer:
        atomic_write_npz(os.path.join(out_dir, record["file"]), **arrays)
    manifest["chunks"].append(record)
    manifest["chunks"].sort(key=lambda c: c["index"])
    if writer:
        atomic_write_json(manifest_path, manifest)


def _differences(old, new, where: str = "") -> list[str]:
    """The fields (dotted paths) in which two sweep definitions differ, each with both
    values: `grid.clearance: [0.0001, 0.0002] in the folder, [0.0001] now`."""
    if isinstance(old, dict) and isinstance(new, dict):
        out = []
        for key in list(old) + [k for k in new if k not in old]:
            path = f"{where}.{key}" if where else str(key)
            if key not in new:
                out.append(f"{path}: {old[key]!r} in the folder, not set now")
            elif key not in old:
                out.append(f"{path}: not set in the folder, {new[key]!r} now")
            else:
                out += _differences(old[key], new[key], path)
        return out
    if old != new:
        return [f"{where}: {old!r} in the folder, {new!r} now"]
    return []


def _wrap(evaluate):
    def features(params, trajectory):
        return {} if evaluate is None else dict(evaluate(params, trajectory))

    return features


def _chunk_done(out_dir, record) -> bool:
    return os.path.exists(os.path.join(out_dir, record["file"]))


def _progress(enabled, total, initial, stream=None):
    """The sweep's progress, updated per finished chunk: a tqdm bar on a terminal; elsewhere
    (a log file, CI, a pipe) one line per chunk, since a bar redrawn by carriage returns
    is one ever-growing line there. `None` when not `enabled`."""
    if not enabled:
        return None
    stream = sys.stderr if stream is None else stream
    if stream.isatty():
        from tqdm import tqdm

        return tqdm(total=total, initial=initial, unit="case", file=stream, desc="sweep")
    return _ChunkLines(total, initial, stream)


class _ChunkLines:
    """Progress as lines (`_progress` off a terminal): cases done of all, elapsed time, and
    the time left at this run's rate (cases done before a `--resume` are not in the rate)."""

    def __init__(self, total, initial, stream):
        self.total, self.done, self.stream = total, initial, stream
        self.start, self.initial = time.monotonic(), initial

    def update(self, cases):
        self.done += cases
        elapsed = time.monotonic() - self.start
        line = f"sweep: {self.done}/{self.total} cases ({100 * self.done / self.total:.0f} %)"
        line += f", {duration_text(elapsed)} elapsed"
        if self.done < self.total and self.done > self.initial:
            left = elapsed * (self.total - self.done) / (self.done - self.initial)
            line += f", about {duration_text(left)} left"
        print(line, file=self.stream, flush=True)

    def close(self):
        pass


def load_sweep(out_dir: str) -> dict:
    """Every finished case of the sweep in `out_dir`, in case order: `{"case": (B,),
    "param_*": (B,), "feature_*": (B,), "result": (B,), ... , "q": (B, N, n) if saved}`, and
    the manifest under `"manifest"`. Raises if a case appears twice."""
    manifest = _read_manifest(os.path.join(out_dir, MANIFEST))
    parts = []
    for record in manifest["chunks"]:
        with np.load(os.path.join(out_dir, record["file"])) as data:
            parts.append({k: data[k] for k in data.files})
    if not parts:
        return {"manifest": manifest, "case": np.zeros(0, dtype=int)}
    out = {k: np.concatenate([p[k] for p in parts]) for k in parts[0] if k != "t"}
    if "t" in parts[0]:
        out["t"] = parts[0]["t"]
    order = np.argsort(out["case"], kind="stable")
    out = {k: (v[order] if k != "t" else v) for k, v in out.items()}
    if len(np.unique(out["case"])) != len(out["case"]):
        raise RuntimeError(f"sweep in {out_dir!r}: a case is recorded twice")
    out["manifest"] = manifest
    return out
