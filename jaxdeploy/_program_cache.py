"""Traced programs kept on disk between processes, so that a second `jaxdeploy simulate` does
not trace and lower its programs again.

JAX's persistent compilation cache (`_compilation_cache`) skips only XLA's backend compile:
every process still traces the Python code into a jaxpr and lowers it to StableHLO, which for
deploy_array's integration is most of a warm run. `jax.export` serializes a lowered program
with the shapes and dtypes of its arguments, and `jax.export.deserialize(...).call(...)` runs
it in another process without the Python code that made it
(https://docs.jax.dev/en/latest/export/export.html; its compiled form then comes from the
persistent compilation cache as before).

`call(fn, *args)` is `fn(*args)` for an `equinox.filter_jit` function `fn`, through that
store. An exported program is the trace of `fn` for one composition of its arguments: its
array leaves are inputs (their values may change), everything else was baked in while
tracing. The entry's key is therefore everything the trace depends on: the package's code
(`code_digest`: every .py and .json file under jaxdeploy/), the versions of jax, jaxlib,
diffrax, equinox, lineax, optimistix and numpy, the platform and devices, the JAX settings
that change a trace, `EQX_ON_ERROR`, `fn`'s name, the tree structure of the arguments (with
their static fields), the shape, dtype and weak type of each array leaf, and the value of
every other leaf. A leaf whose value cannot be written down exactly (an object or a function
that closes over data) makes the call uncacheable, and it runs as `fn(*args)`; so does a call
under a transformation (traced arguments), one in a process where equinox's runtime checks
are host callbacks (`EQX_ON_ERROR=raise`, its default: the command line sets `nan`, see
`_compilation_cache`) and one whose program JAX cannot export (another host callback, e.g. a
progress bar; it warns once).

Every call through the store runs the exported program, the first (which writes the entry)
as well as the later ones (which read it), so a result does not depend on whether the entry
existed; the program is the one `jax.jit(fn)` lowers, and tests/test_program_cache.py checks
that the results are bit-identical to `fn(*args)`. Its compiled form is kept beside the entry
too (`<key>-<machine>.executable`, `jax.experimental.serialize_executable`), so that a later
process neither lowers the exported program again nor looks it up in JAX's compilation cache:
it loads the executable and runs it (`_executable`).

Location: off unless a caller enables it (`enable`; the command line does, beside the
compilation cache: `_compilation_cache.cache_dir()` + `-programs`, so `JAXDEPLOY_CACHE_DIR`
moves it and `JAXDEPLOY_CACHE_DIR=off` turns it off). An entry that cannot be read is ignored
with a warning and written again; a store that cannot be written is skipped (tracing again is
slower, not wrong). Entries hold pickled tree structures: like the compilation cache, the
folder must be writable by its user only.
"""

from __future__ import annotations

import functools
import hashlib
import inspect
import json
import os
import pathlib
import pickle
import platform
import sys
import tempfile
import threading
import time
import warnings
from contextlib import contextmanager

# The `jax.monitoring` time span of reading a compiled program back (`_executable`).
LOAD_EVENT = "/jaxdeploy/program_cache/load_executable_duration"

_folder: str | None = None
_unexportable: set[str] = set()
_loaded: dict[str, tuple] = {}
_compiled: dict[str, object] = {}
_hook = threading.local()
# Kept executables being read ahead in a background thread (`_read_ahead`), by path, and
# those this process ran, by path in the order of first use, with whether they call LAPACK.
_ahead: dict[str, object] = {}
_run: dict[str, bool] = {}
_taken_ahead: list[str] = []

# JAX settings that change what a function traces to (dtypes, precision, promotion rules).
_TRACE_SETTINGS = (
    "jax_enable_x64",
    "jax_default_matmul_precision",
    "jax_numpy_dtype_promotion",
    "jax_numpy_rank_promotion",
    "jax_default_prng_impl",
    "jax_debug_nans",
    "jax_debug_infs",
)
# Modules whose functions may be leaves of a cached call's arguments: their code is in the
# key (the package's digest, the libraries' versions), so a module-level function of theirs
# is identified by its qualified name.
_KEYED_MODULES = ("jaxdeploy", "jax", "diffrax", "equinox", "lineax", "optimistix", "numpy")


def enable(folder: str | None) -> None:
    """Store programs in `folder` from now on (None: off)."""
    global _folder
    _folder = folder


def folder() -> str | None:
    return _folder


@contextmanager
def when_traced(callback):
    """Within this block, `callback()` is called once, in this thread, when the first call
    through the store has its program (traced and exported, or read back) and is about to
    compile and run it; inside `ahead_of_time()`, once the program is lowered for XLA's
    compile (or its executable read back). From then on the thread mostly waits on XLA,
    which does not hold Python's GIL, so a caller may start tracing something else in
    another thread. Not called when no call goes through the store (off, or uncacheable);
    None: nothing."""
    with _thread_setting("callback", callback):
        yield


@contextmanager
def _thread_setting(name: str, value):
    """`_hook.<name>` = `value` in this thread within the block, as it was after it."""
    previous = getattr(_hook, name, None)
    setattr(_hook, name, value)
    try:
        yield
    finally:
        setattr(_hook, name, previous)


def _traced() -> None:
    callback = getattr(_hook, "callback", None)
    if callback is not None:
        _hook.callback = None
        callback()


@functools.cache
def code_digest() -> str:
    """SHA-256 of every .py and .json file under jaxdeploy/ (names and contents)."""
    package = pathlib.Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for path in sorted(package.rglob("*")):
        if path.suffix in (".py", ".json") and "__pycache__" not in path.parts:
            digest.update(str(path.relative_to(package)).encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()


def environment() -> str:
    """What every entry's key starts from: the package's code digest, the libraries'
    versions, the platform and the devices (JSON text)."""
    return _environment()


def trace_settings() -> dict:
    """The JAX settings that change what a function traces to, as text."""
    import jax

    return {name: str(getattr(jax.config, name, None)) for name in _TRACE_SETTINGS}


@functools.cache
def _environment() -> str:
    import diffrax
    import equinox
    import jax
    import jaxlib
    import lineax
    import numpy as np
    import optimistix

    versions = [m.__version__ for m in (jax, jaxlib, diffrax, equinox, lineax, optimistix, np)]
    return json.dumps(
        {
            "code": code_digest(),
            "versions": versions,
            "platform": [platform.platform(), platform.machine()],
            "devices": [str(d) for d in jax.devices()],
        }
    )


def _leaf_key(leaf):
    """An exact description of a non-array leaf, or None when it has none."""
    if leaf is None or type(leaf) in (bool, int, float, complex, str):
        return [type(leaf).__name__, repr(leaf)]  # repr of a float is exact (round-trips)
    if inspect.isfunction(leaf):
        module = leaf.__module__ or ""
        # A closure or a nested function carries data the name does not say.
        if (
            leaf.__closure__ is None
            and "<" not in leaf.__qualname__
            and module.split(".")[0] in _KEYED_MODULES
        ):
            return ["function", f"{module}:{leaf.__qualname__}"]
    return None


def equinox_on_error() -> str:
    """What equinox's runtime checks do in this process: `EQX_ON_ERROR` as equinox read it
    when it was imported (a later change of the variable has no effect on it)."""
    import equinox  # noqa: F401

    config = sys.modules.get("equinox._config")
    return getattr(config, "EQX_ON_ERROR", None) or os.environ.get("EQX_ON_ERROR", "raise")


def key(fn, args) -> str | None:
    """The store's key of `fn(*args)` (see the module docstring), or None if uncacheable."""
    import jax

    on_error = equinox_on_error()
    if on_error not in ("nan", "off") or jax.config.jax_disable_jit:
        return None  # equinox's checks are host callbacks; without jit there is no program
    leaves, treedef = jax.tree.flatten(args)
    structure = _structure(treedef)
    if " at 0x" in structure:  # a static field identified by its address
        return None
    described = []
    for leaf in leaves:
        if isinstance(leaf, jax.core.Tracer):
            return None  # under jit/vmap/grad: the caller's trace owns this call
        if _is_array(leaf):
            shape, dtype, weak = _aval(leaf)
            described.append(["array", list(shape), _dtype_name(dtype), weak])
            continue
        description = _leaf_key(leaf)
        if description is None:
            return None
        described.append(description)
    record = [
        _environment(),
        trace_settings(),
        on_error,
        _function_name(fn),
        structure,
        described,
    ]
    return hashlib.sha256(json.dumps(record).encode()).hexdigest()


def call(fn, *args):
    """`fn(*args)` (`fn` an `equinox.filter_jit` function), through the store when it is on
    and the call is cacheable (module docstring). Full garbage collections wait while it
    traces, lowers and compiles (`_collector`). Inside `ahead_of_time()`, the program is made
    ready and `ProgramReady` is raised instead of running it."""
    from ._collector import full_collections_deferred

    with full_collections_deferred():
        return _call(fn, *args)


class ProgramReady(Exception):
    """Raised by `call` inside `ahead_of_time()` once the call's program is traced (or read
    back) and compiled: it unwinds the caller (e.g. `simulate`) before anything runs."""

    def __init__(self, ready: bool):
        super().__init__("program ready" if ready else "program not cacheable")
        self.ready = ready


@contextmanager
def ahead_of_time():
    """Within this block (in this thread), `call` makes its program ready without running
    it: it computes the entry's key, reads the entry back or traces and stores it, compiles
    (or loads) its executable and raises `ProgramReady` (`.ready`: False when the call is not
    cacheable, which makes nothing). Array arguments may be `jax.ShapeDtypeStruct`s: only
    their shapes, dtypes and weak types enter the key and the trace. A later `call` with
    arrays of those shapes, in any thread, then runs the program at once; one that comes
    while it is being made waits for it (one lock per key) instead of making it again.

    For a command that knows its run's shapes before its initial state exists: the run's
    compile then overlaps the assembly's (`jaxdeploy simulate`, `commands/simulate.py`)."""
    with _thread_setting("ahead", True):
        yield


_key_locks: dict[str, threading.Lock] = {}
_key_locks_guard = threading.Lock()


def _key_lock(cache_key: str) -> threading.Lock:
    with _key_locks_guard:
        return _key_locks.setdefault(cache_key, threading.Lock())


def _is_array(x) -> bool:
    """An array leaf of a call's arguments: an array, or its shape alone (`ahead_of_time`)."""
    import equinox as eqx
    import jax

    return eqx.is_array(x) or isinstance(x, jax.ShapeDtypeStruct)


def _aval(x):
    """`(shape, dtype, weak_type)` of an array leaf (`_is_array`)."""
    import jax
    import numpy as np

    if isinstance(x, jax.ShapeDtypeStruct):
        return x.shape, x.dtype, bool(x.weak_type)
    if isinstance(x, np.ndarray):  # what `jax.typeof` says of it, without building it
        return x.shape, x.dtype, False
    aval = jax.typeof(x)
    return aval.shape, aval.dtype, aval.weak_type


def _function_name(fn) -> str:
    """`module:qualname` of `fn`, or its repr (an `equinox.filter_jit` wrapper's is printed
    by wadler_lindig: 0.3 ms a call), kept per function object."""
    known = _names.get(id(fn))
    if known is None or known[0] is not fn:
        known = _names[id(fn)] = (fn, f"{fn.__module__}:{getattr(fn, '__qualname__', repr(fn))}")
    return known[1]


def _dtype_name(dtype) -> str:
    """`dtype.name` (a Python property of NumPy's, ~4 µs), kept per dtype."""
    name = _dtype_names.get(dtype)
    if name is None:
        name = _dtype_names[dtype] = dtype.name
    return name


_names: dict = {}
_dtype_names: dict = {}
# `str(treedef)` of the calls' argument structures, by structure: a mechanism's string (its
# static fields printed) was most of the cost of `key` (0.7 ms of a 1.7 ms warm `simulate`
# call). Structures are equal when their node types and static fields compare equal, the
# rule by which `jax.jit` and `equinox.filter_jit` reuse a compiled program: keying the store
# by it reuses no more than they do. At most `_STRUCTURES_KEPT` are kept (a sweep over a
# static option makes a new one per value; a mechanism's string is tens of kB).
_structures: dict = {}
_STRUCTURES_KEPT = 256


def _structure(treedef) -> str:
    """`str(treedef)`, kept per structure (`_structures`)."""
    try:
        known = _structures.get(treedef)
    except TypeError:  # a static field that cannot be hashed
        return str(treedef)
    if known is None:
        if len(_structures) >= _STRUCTURES_KEPT:
            _structures.clear()
        known = _structures[treedef] = str(treedef)
    return known


def _call(fn, *args):
    import jax

    ahead = bool(getattr(_hook, "ahead", False))
    where = _folder
    cache_key = None if where is None else key(fn, args)
    if cache_key is None or not folder_is_private(where, "program cache"):
        if ahead:
            raise ProgramReady(False)
        return fn(*args)
    path = os.path.join(where, f"{cache_key}.jaxexport")
    arrays = [x for x in jax.tree.leaves(args) if _is_array(x)]
    # The trace runs every call through the store in `fn`'s body as part of it (their
    # arguments are traced): `ahead_of_time` is this call's alone.
    with _key_lock(cache_key), _thread_setting("ahead", False):
        entry = _entry(fn, args, cache_key, path)
    if entry is None:
        if ahead:
            raise ProgramReady(False)
        return fn(*args)
    if ahead:
        with _key_lock(cache_key):
            _executable(cache_key, path, entry[0], arrays)
        _traced()  # if the executable was read back (no compile: `_lowered` did not call it)
        raise ProgramReady(True)
    _traced()
    exported, skeleton = entry
    with _key_lock(cache_key):
        executable = _executable(cache_key, path, exported, arrays)
    results = iter(executable(*arrays))
    return jax.tree.map(lambda leaf: next(results) if leaf is _ARRAY else leaf, skeleton)


def _entry(fn, args, cache_key, path):
    """`(exported, skeleton)` of the store's entry for `fn(*args)`: this process's, else read
    from `path`, else traced, exported and stored there; None when JAX cannot export it."""
    # Read once per process: the same `Exported` object reuses its compiled executable, where
    # a new one read from the disk would be compiled again (a fit or a sweep calls again).
    entry = _loaded.get(cache_key) or _load(path, cache_key)
    if entry is None:
        payload = None if cache_key in _unexportable else _export(fn, args, cache_key)
        if payload is None:
            _unexportable.add(cache_key)  # not tried again in this process
            return None
        _store(path, payload)
        # An executable kept beside an entry that was missing or discarded belongs to the
        # program that was there before: compile the new one afresh.
        try:
            os.unlink(_executable_path(path))
        except OSError:
            pass
        # Run what was stored, read back: deserializing drops weak types, so the program
        # that wrote the entry would give outputs that differ from a later hit's in them
        # (and so miss the keys of the programs they flow into).
        entry = _decode(payload)
    _loaded[cache_key] = entry
    return entry


def _executable(cache_key, path, exported, arrays):
    """The compiled form of `exported` for `arrays`: this process's, else the one kept beside
    the entry (`_executable_path`), else compiled now and kept there.

    Calling `exported` itself would lower it in every process (`jax.export`'s call parses the
    stored module into a new one) and look the result up in JAX's compilation cache by a hash
    of that module: on a warm `jaxdeploy simulate` those two steps were most of loading its
    programs. The executable is what `jax.jit(exported.call)` compiles, serialized with
    `jax.experimental.serialize_executable`, so its results are those of the exported program
    (tests/test_program_cache.py). It is kept per machine (`_machine`): compiled code is
    specific to the processor and XLA's flags."""
    import jax

    compiled = _compiled.get(cache_key)
    if compiled is not None:
        return compiled
    lapack = b"lapack_" in bytes(exported.mlir_module_serialized)
    if lapack:
        prepare_lapack()
    if jax.device_count() > 1:
        # A kept executable is read back onto every device of the process: a one-device
        # program then fails with "Expected args to execute_sharded_on_local_devices to have
        # 4 shards" (jax 0.10.2, 4 forced host devices: the sweep's probe). Compiled, not kept.
        compiled = _lowered(_placed_call(exported), arrays).compile()
        _compiled[cache_key] = compiled
        return compiled
    where = _executable_path(path)
    _run.setdefault(where, lapack)
    began = time.time()
    ahead = _ahead.pop(where, None)
    compiled = None if ahead is None else ahead.result()
    if compiled is not None:
        _taken_ahead.append(where)
    else:
        compiled = _load_executable(where)
    if compiled is None:
        compiled = _compile_and_keep(exported, arrays, where)
    else:  # reported like JAX's compile events (a command's phases count it as compiling)
        jax.monitoring.record_event_time_span(LOAD_EVENT, began, time.time())
        compiled = _Kept(compiled, where, exported, arrays)
    _compiled[cache_key] = compiled
    return compiled


def _placed_call(exported):
    """`exported.call`, placed on the devices it was exported for: a program of several
    devices (`jax.shard_map`: `optimize.BatchObjective`) must be called with its arguments
    laid out over as many ("exported for 2 devices and is called in a context with 1
    devices", jax 0.10.2), the layout it was exported with (`Exported.in_shardings_jax`) on
    the process's first devices, in order, as the traced program's mesh took them."""
    import jax
    import numpy as np

    if exported.nr_devices == 1:
        return exported.call
    mesh = jax.sharding.Mesh(np.array(jax.devices()[: exported.nr_devices]), ("devices",))
    # A layout the program left open (a `shard_map` inside a jit: the jit's own arguments
    # and results have none) is whole on every device: it is the device count that counts.
    whole = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec())

    def placed(layouts, count):
        try:
            shardings = layouts(mesh)
        except ValueError:
            # Named layouts over another mesh: a program whose `shard_map` sits inside an inner
            # `jax.jit` (the sweep's chunk, `sweep._chunk_program`) records its open layouts
            # over a mesh without axes, which jax 0.10.2 refuses to move onto this one ("does
            # not match the mesh used for export"). Whole on every device, as open layouts are.
            shardings = [None] * count
        return [whole if s is None else s for s in shardings]

    return jax.jit(
        exported.call,
        in_shardings=tuple(placed(exported.in_shardings_jax, len(exported.in_avals))),
        out_shardings=placed(exported.out_shardings_jax, len(exported.out_avals)),
    )


def _lowered(fn, arrays):
    """`jax.jit(fn)` lowered for `arrays`; then `when_traced`'s callback, if any: what
    follows is XLA's compile, which leaves Python's GIL free for another thread's trace."""
    import jax

    lowered = jax.jit(fn).lower(*arrays)
    _traced()
    return lowered


def _compile_and_keep(exported, arrays, where):
    """Compile `exported` for `arrays` and keep the executable at `where`, unless XLA's
    code came from JAX's persistent compilation cache: such an executable serializes without
    its object code, and running it read back fails with "NOT_FOUND: Function ... not found"
    (jax 0.10.2, seen on the second of two in-process `jaxdeploy simulate` runs)."""
    import jax

    _watch_cache_hits()
    hits = getattr(_hits, "count", 0)
    compiled = _lowered(exported.call, arrays).compile()
    if getattr(_hits, "count", 0) == hits:
        _store_executable(where, compiled)
        return compiled

    # Read from JAX's cache (its entry written by an earlier process, e.g. before a change of
    # the package's code, which changes this store's key but not the program): compiled
    # under a name of this entry's own, which JAX's cache has not seen (the module's name is
    # part of its key), XLA compiles it once more and the executable is kept. Without it no
    # later process would keep one either, and each would lower the program again (and load
    # scipy's LAPACK kernels for that). Same program, same compiler: the same code.
    def kept(*arrays):
        return exported.call(*arrays)

    kept.__name__ = kept.__qualname__ = f"kept_{os.path.basename(where)[:16]}"

    hits = getattr(_hits, "count", 0)
    again = jax.jit(kept).lower(*arrays).compile()
    if getattr(_hits, "count", 0) == hits:
        _store_executable(where, again)
        return again
    return compiled


_hits = threading.local()  # persistent-cache hits of this thread's compiles


@functools.cache
def _watch_cache_hits() -> None:
    import jax

    def count(event, **_):
        if event == "/jax/compilation_cache/cache_hits":
            _hits.count = getattr(_hits, "count", 0) + 1

    jax.monitoring.register_event_listener(count)


class _Kept:
    """An executable read back from the disk; if it cannot run (code missing from what was
    kept), the file is discarded with one line and the program compiled again."""

    def __init__(self, compiled, where, exported, arrays):
        self.compiled, self.where, self.exported, self.arrays = compiled, where, exported, arrays

    def __call__(self, *arrays):
        import jax

        try:
            return self.compiled(*arrays)
        except jax.errors.JaxRuntimeError as err:
            if "NOT_FOUND" not in str(err) and "shards" not in str(err):
                raise
            warnings.warn(
                f"discarding the kept compiled program {self.where}, which cannot run ({err}); "
                "compiling it again",
                RuntimeWarning,
                stacklevel=2,
            )
            try:
                os.unlink(self.where)
            except OSError:
                pass
            self.compiled = _compile_and_keep(self.exported, self.arrays, self.where)
            return self.compiled(*arrays)


@functools.cache
def _machine() -> str:
    """What compiled code depends on besides the entry's key: the processor (its model and
    instruction-set flags) and XLA's flags."""
    try:
        with open("/proc/cpuinfo") as f:
            described = [line for line in f if line.startswith(("model name", "flags"))][:2]
    except OSError:
        described = [platform.processor()]
    record = [described, os.environ.get("XLA_FLAGS", "")]
    return hashlib.sha256(json.dumps(record).encode()).hexdigest()[:16]


def _executable_path(path: str) -> str:
    return f"{path.removesuffix('.jaxexport')}-{_machine()}.executable"


def prepare_lapack() -> None:
    """What `jax.export` does before lowering a program with a LAPACK call, and JAX's lowering
    of one: load the LAPACK kernels (scipy's), which a program read back calls."""
    import numpy as np
    from jaxlib import lapack

    lapack.prepare_lapack_call("getrf_ffi", np.float64)


def reading_ahead(where: str, future) -> None:
    """`future` will hold the executable kept at `where` (or None), read by `_read_ahead`:
    `_executable` takes it instead of reading the file itself."""
    _ahead[where] = future


def executables_run() -> dict[str, bool]:
    """The kept executables' paths this process ran, in the order of first use, each with
    whether its program calls LAPACK (`_read_ahead` remembers them)."""
    return dict(_run)


def executables_read_ahead() -> list[str]:
    """The kept executables this process took from `_read_ahead` instead of reading them."""
    return list(_taken_ahead)


def machine() -> str:
    """The machine part of a kept executable's name (`_machine`)."""
    return _machine()


def store_file(path: str, payload: bytes) -> None:
    """Write `payload` at `path` whole (`_store`; a folder that cannot be written is skipped)."""
    _store(path, payload)


def load_executable_quietly(path):
    """`_load_executable` without its warning (the caller's fallback reads the file again and
    warns then)."""
    return _load_executable(path, quiet=True)


def _load_executable(path, quiet: bool = False):
    """The executable kept at `path`, or None when there is none or it cannot be loaded."""
    from jax.experimental.serialize_executable import deserialize_and_load

    try:
        with open(path, "rb") as f:
            payload = f.read()
    except OSError:
        return None
    try:
        stored = pickle.loads(payload)
        return deserialize_and_load(stored["executable"], stored["in_tree"], stored["out_tree"])
    except Exception as err:  # noqa: BLE001 - any unreadable executable is compiled again
        if quiet:
            return None
        warnings.warn(
            f"ignoring the unreadable compiled program {path} ({type(err).__name__}: {err}); "
            "compiling it again",
            RuntimeWarning,
            stacklevel=4,
        )
        return None


def _store_executable(path, compiled) -> None:
    from jax.experimental.serialize_executable import serialize

    try:
        executable, in_tree, out_tree = serialize(compiled)
    except Exception:  # noqa: BLE001 - not serializable here: compiled again next time
        return
    payload = pickle.dumps({"executable": executable, "in_tree": in_tree, "out_tree": out_tree})
    _store(path, payload)


class _ArrayMark:
    """Where an output leaf is an array (the exported program's next result)."""

    def __reduce__(self):
        return "_ARRAY"  # unpickles as this module's one instance


_ARRAY = _ArrayMark()


def _export(fn, args, cache_key: str) -> bytes | None:
    """The store's entry for `fn(*args)`: its exported program and its output with the arrays
    marked, serialized; None when JAX cannot export or serialize it (then the caller runs
    `fn` as it is, which raises again if the error was the traced code's own)."""
    import equinox as eqx
    import jax

    leaves, treedef = jax.tree.flatten(args)
    avals = [_aval(x) for x in leaves if _is_array(x)]
    shapes = [jax.ShapeDtypeStruct(shape, dtype, weak_type=weak) for shape, dtype, weak in avals]
    output = {}

    def flat(*arrays):
        given = iter(arrays)
        full = [next(given) if _is_array(x) else x for x in leaves]
        out_leaves, out_treedef = jax.tree.flatten(fn(*jax.tree.unflatten(treedef, full)))
        # The output with each array replaced by a mark, stored by pickling the objects
        # themselves (a pickled tree structure loses equinox's sentinels).
        marked = [_ARRAY if eqx.is_array(x) else x for x in out_leaves]
        output["skeleton"] = jax.tree.unflatten(out_treedef, marked)
        return [x for x in out_leaves if eqx.is_array(x)]

    # JAX reports the trace under this name (`jax.monitoring`'s compile events): a process
    # that traces `fn` for the store shows "exported_" + its name (tests count these).
    flat.__name__ = flat.__qualname__ = "exported_" + getattr(fn, "__name__", "program")
    try:
        exported = jax.export.export(jax.jit(flat))(*shapes)
        program = bytes(exported.serialize())
        # What the entry is for (its key) and a digest of the program: `_load` checks both,
        # so a file under another key or a damaged one is discarded, never run.
        record = {"key": cache_key, "digest": hashlib.sha256(program).hexdigest()}
        return pickle.dumps({"program": program, **record, **output})
    except Exception as err:  # noqa: BLE001
        # e.g. a host callback (a progress bar, equinox's checks under EQX_ON_ERROR=raise).
        warnings.warn(
            f"{getattr(fn, '__qualname__', fn)} is not kept in the program cache: JAX could "
            f"not export it ({type(err).__name__}: {str(err)[:200]})",
            RuntimeWarning,
            stacklevel=3,
        )
        return None


class EntryMismatch(ValueError):
    """A program cache entry that is not what its name says (another key, a wrong digest)."""


def _decode(payload: bytes, cache_key: str | None = None):
    """`(exported, skeleton)` of a stored entry; with `cache_key`, an entry recorded for
    another key or whose program does not match its digest raises `EntryMismatch`."""
    import jax

    stored = pickle.loads(payload)
    if cache_key is not None:
        if stored.get("key") != cache_key:
            raise EntryMismatch("it was written for another program (its recorded key differs)")
        if hashlib.sha256(stored["program"]).hexdigest() != stored.get("digest"):
            raise EntryMismatch("its program does not match its digest")
    return jax.export.deserialize(bytearray(stored["program"])), stored["skeleton"]


def _load(path, cache_key: str | None = None):
    """The entry at `path` decoded (and checked against `cache_key`), or None when there is
    none or it cannot be used: then it is traced again and the entry rewritten."""
    try:
        with open(path, "rb") as f:
            payload = f.read()
    except OSError:
        return None
    try:
        return _decode(payload, cache_key)
    except EntryMismatch as err:
        warnings.warn(
            f"program cache: discarding the entry {path}: {err}; tracing the program again "
            "and rewriting it (if this recurs, delete the folder)",
            RuntimeWarning,
            stacklevel=3,
        )
        return None
    except Exception as err:  # noqa: BLE001 - any unreadable entry is traced again
        warnings.warn(
            f"ignoring the unreadable program cache entry {path} ({type(err).__name__}: "
            f"{err}); tracing the program again",
            RuntimeWarning,
            stacklevel=3,
        )
        return None


_unsafe_seen: set[str] = set()


def folder_is_private(where: str, what: str) -> bool:
    """Whether a cache folder of pickled entries may be read (`what` names the cache in the
    warning): a folder another user could write into (owned by someone else, or
    group/other-writable) is not read (a missing folder is safe: `_store` creates it private
    to its user's umask)."""
    try:
        info = os.stat(where)
    except OSError:
        return True
    owner_ok = not hasattr(os, "getuid") or info.st_uid == os.getuid()
    if owner_ok and not info.st_mode & 0o022:
        return True
    if where not in _unsafe_seen:
        _unsafe_seen.add(where)
        warnings.warn(
            f"{what}: not reading {where}: it is writable by other users (mode "
            f"{info.st_mode & 0o777:o}, owner uid {info.st_uid}) and its entries are pickles; "
            f"run `chmod go-w {where}` or choose another JAXDEPLOY_CACHE_DIR",
            RuntimeWarning,
            stacklevel=3,
        )
    return False


def discard_entry(path: str, cache: str, why: str, redo: str) -> None:
    """Delete the damaged or foreign entry `path` of `cache` (its name in the message) and
    say so in one line on stderr, with `why` and what happens instead (`redo`, e.g.
    "building the scene again"). Returns None: what a loader returns for "not stored"."""
    print(
        f"warning: {cache}: discarding {path}: {why}; {redo} (if this recurs, delete the folder)",
        file=sys.stderr,
    )
    try:
        os.unlink(path)
    except OSError:
        pass
    return None


def _store(path: str, payload: bytes) -> None:
    where = os.path.dirname(path)
    try:
        os.makedirs(where, exist_ok=True)
        # Written whole, then renamed: a reader never sees half an entry.
        fd, tmp = tempfile.mkstemp(dir=where, suffix=".tmp")
        with os.fdopen(fd, "wb") as f:
            f.write(payload)
        os.replace(tmp, path)
    except OSError:
        pass
