"""A scene's built mechanism and initial state, kept on disk between `jaxdeploy simulate` runs.

Building slider_crank's mechanism dispatches a few dozen small array operations one by one,
and its initial state is two assembly programs (Gauss–Newton on the constraints, then the
velocities and the index-1 accelerations), whose executables must be read back and whose
LAPACK calls load scipy's kernels: about a second of a warm run that ends where the previous
one did. Both are functions of the scene's name, options and parameter values alone (and of
the code and libraries that compute them), which the command line knows before it builds
anything. So the pair is stored under the key of exactly that: the package's code digest,
the libraries' versions, the platform and devices, the JAX settings that change a trace,
`EQX_ON_ERROR`, the scene's name and options, and the type and exact `repr` of every
parameter value. A hit is the pickled pair as the first run built it, arrays with their
dtypes and weak types, so every program it flows into has the key it had then and gives
bit-identical results (tests/test_scene_cache.py).

An entry records its key and a digest of its contents: one under another key, a damaged one
or one that cannot be unpickled is discarded with one line on stderr, built again and
rewritten. Entries are pickles: like the program cache, a folder writable by other users is
not read. Location: beside the compilation cache (`_compilation_cache.cache_dir()` +
`-scenes`); off when it is off (`JAXDEPLOY_CACHE_DIR=off`). A folder that cannot be written
is skipped (building again is slower, not wrong).
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle

from .._compilation_cache import cache_dir
from .._program_cache import (
    discard_entry,
    environment,
    equinox_on_error,
    folder_is_private,
    trace_settings,
)


def folder() -> str | None:
    base = cache_dir()
    return None if base is None else base.rstrip(os.sep) + "-scenes"


def key(scene, params) -> str | None:
    """The cache key of `scene` built with `params` (module docstring), or None when a value
    cannot be written down exactly (not a plain number, bool or string)."""
    described = {}
    for name, value in sorted(params.items()):
        if type(value) not in (bool, int, float, str):
            return None
        described[name] = [type(value).__name__, repr(value)]  # a float's repr round-trips
    record = [
        environment(),
        trace_settings(),
        equinox_on_error(),
        scene.name,
        repr(sorted(scene.options.items())),
        described,
    ]
    return hashlib.sha256(json.dumps(record).encode()).hexdigest()


def built(scene, params, build, assemble):
    """`(mechanism, initial_state, facts, source)`: read back, or `mechanism = build()`,
    `initial, facts = assemble(mechanism)` and stored (source "cache" or "built"; `facts`:
    plain data the caller derives from the mechanism and wants kept with it, e.g. numbers
    whose computation traces). Exceptions of `build` and `assemble` propagate and nothing is
    stored."""
    where = folder()
    cache_key = None if where is None else key(scene, params)
    path = None if cache_key is None else os.path.join(where, f"{cache_key}.pickle")
    if path is not None and folder_is_private(where, "scene cache"):
        stored = load(path, cache_key)
        if stored is not None:
            return (*stored, "cache")
    mechanism = build()
    initial, facts = assemble(mechanism)
    if path is not None:
        store(path, cache_key, (mechanism, initial, facts))
    return mechanism, initial, facts, "built"


def load(path: str, cache_key: str):
    """What is stored at `path` for `cache_key`, or None (none stored, or discarded)."""
    try:
        with open(path, "rb") as f:
            payload = f.read()
    except OSError:
        return None
    try:
        entry = pickle.loads(payload)
        if entry.get("key") != cache_key:
            return _discard(path, "it was written for another scene or parameters")
        if hashlib.sha256(entry["contents"]).hexdigest() != entry.get("digest"):
            return _discard(path, "its contents do not match their digest")
        return pickle.loads(entry["contents"])
    except Exception as err:  # noqa: BLE001 - any unreadable entry is built again
        return _discard(path, f"it cannot be read ({type(err).__name__}: {str(err)[:120]})")


def _discard(path: str, why: str) -> None:
    return discard_entry(path, "scene cache", why, "building the scene again")


def store(path: str, cache_key: str, stored) -> None:
    from ..io import atomic_write_bytes

    try:
        contents = pickle.dumps(stored)
    except Exception:  # noqa: BLE001 - an element that cannot be pickled: built every time
        return
    entry = {"key": cache_key, "digest": hashlib.sha256(contents).hexdigest()}
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        atomic_write_bytes(path, pickle.dumps({**entry, "contents": contents}))
    except OSError:
        pass
