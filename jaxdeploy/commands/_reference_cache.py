"""The reference run of `jaxdeploy simulate`, kept on disk between runs.

deploy_array's deviations from the ideal mechanism need a second simulation, of the same
array with ideal joints (`batch.reference_run`). It depends on the parameters the ideal array
uses — not on the clearances and roughnesses a study varies — on the saved
times and on its step control, so one computed reference serves every later run that differs
from it only in its joints. It is stored under the key of everything it is a function of: the
package's code (every .py and .json file under jaxdeploy/, so a code change is a miss), the
versions of jax/jaxlib/diffrax/equinox/numpy, the platform and device, `EQX_ON_ERROR`, the
ideal scene's name, options and the parameters it uses (not those its options make
irrelevant), the step control, and the saved times. A hit returns the arrays the simulation
wrote, bit for bit. Within one process (a sweep summarizing its cases) a reference is also
kept in memory.

Location: beside the compilation cache (`_compilation_cache.cache_dir()` + `-references`);
off when that cache is off (`JAXDEPLOY_CACHE_DIR=off`). A folder that cannot be created or
written, or that other users could write into, is not used, with one line saying so
(`_compilation_cache.usable_folder`; computing the reference again is slower, not wrong).
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
from typing import NamedTuple

import numpy as np

from .._compilation_cache import cache_dir, usable_folder
from .._program_cache import code_digest, discard_entry


class StoredRun(NamedTuple):
    """A reference run read back from the cache: the saved times `ts` [s] and states `q`,
    `v`, `qdd`, `lam` (as `Trajectory` has them), its `status()` and its scene's scalar
    `events` (`Scene.events`: e.g. the located lock time, which the saved states alone do not
    give independently of the save grid)."""

    ts: np.ndarray
    q: np.ndarray
    v: np.ndarray
    qdd: np.ndarray
    lam: np.ndarray
    status_text: str
    events: dict

    @property
    def ok(self) -> bool:
        return self.status_text == "ok"

    def status(self) -> str:
        return self.status_text


def folder() -> str | None:
    """The cache's folder, or None: caches off, or a folder that cannot be used safely
    (`_compilation_cache.usable_folder`: reported once, and references are computed)."""
    base = cache_dir()
    if base is None:
        return None
    where = base.rstrip(os.sep) + "-references"
    return where if usable_folder(where, "reference cache") else None


def key(scene, params, ts, control) -> str:
    """The cache key of `scene`'s reference run (see the module docstring)."""
    import diffrax
    import equinox
    import jax
    import jaxlib

    ideal = scene.ideal_counterpart()
    unused = ideal.ignored_params()
    shared = {
        k: float(v) for k, v in sorted(params.items()) if k in ideal.params and k not in unused
    }
    record = {
        "code": code_digest(),
        "versions": [
            jax.__version__,
            jaxlib.__version__,
            diffrax.__version__,
            equinox.__version__,
            np.__version__,
        ],
        "platform": [platform.platform(), platform.machine(), str(jax.devices()[0])],
        "eqx_on_error": os.environ.get("EQX_ON_ERROR"),
        "scene": [ideal.name, ideal.options, shared],
        "control": [control.to_json(), repr(control)],
        "ts": hashlib.sha256(np.ascontiguousarray(ts, dtype=np.float64).tobytes()).hexdigest(),
    }
    return hashlib.sha256(json.dumps(record, sort_keys=True, default=str).encode()).hexdigest()


_in_memory: dict = {}


def reference(scene, params, ts, compute):
    """`scene`'s reference run at the saved times `ts`: from memory, from the disk, or
    `compute()` (then kept). **Returns:** `(run, source)`, source "memory", "disk" or
    "computed"."""
    cache_key = key(scene, params, ts, scene.ideal_counterpart().default_control)
    if cache_key in _in_memory:
        return _in_memory[cache_key], "memory"
    run, source = load(cache_key), "disk"
    if run is None:
        run, source = compute(), "computed"
        store(cache_key, run, reference_events(scene, params, run))
    _in_memory[cache_key] = run
    return run, source


def reference_events(scene, params, run) -> dict:
    """`{name: float}`: the ideal counterpart's `Scene.events` of its reference `run`."""
    ideal = scene.ideal_counterpart()
    shared = {k: v for k, v in params.items() if k in ideal.params}
    mechanism = ideal.build(ideal.resolve_params(shared))
    return {k: float(v) for k, v in ideal.events(mechanism, run).items()}


ARRAYS = ("ts", "q", "v", "qdd", "lam")


def digest(arrays, events_text: str = "") -> str:
    """SHA-256 of the reference's arrays (shapes, dtypes and bytes, in `ARRAYS` order) and
    of its events (as stored, JSON text)."""
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(f"{a.shape}{a.dtype}".encode())
        h.update(a.tobytes())
    h.update(events_text.encode())
    return h.hexdigest()


def load(cache_key: str) -> StoredRun | None:
    """The stored reference of `cache_key`, or None: none stored, or an entry that cannot be
    read, records another key or whose arrays do not match their digest (an edited file);
    such an entry is discarded with one line on stderr, computed again and rewritten."""
    where = folder()
    path = None if where is None else os.path.join(where, f"{cache_key}.npz")
    if path is None or not os.path.exists(path):
        return None
    try:
        with np.load(path) as data:
            arrays = [data[k] for k in ARRAYS]
            events_text = str(data["events"])
            recorded = (str(data["key"]), str(data["digest"]), str(data["status"]))
    except (OSError, KeyError, ValueError) as err:
        return _discard(path, f"it cannot be read ({type(err).__name__})")
    if recorded[0] != cache_key:
        return _discard(path, "it records another reference run's key")
    if recorded[1] != digest(arrays, events_text):
        return _discard(path, "its numbers do not match their digest (the file was changed)")
    return StoredRun(*arrays, recorded[2], json.loads(events_text))


def _discard(path: str, why: str) -> None:
    return discard_entry(path, "reference cache", why, "computing the reference again")


def store(cache_key: str, run, events: dict) -> None:
    """Keep a successful reference run and its `events`; a failed one is never stored (it is
    computed again and its failure reported again)."""
    from ..io import atomic_write_npz

    where = folder()
    if where is None or not run.ok:
        return
    events_text = json.dumps(events)
    try:
        os.makedirs(where, exist_ok=True)
        atomic_write_npz(
            os.path.join(where, f"{cache_key}.npz"),
            ts=run.ts,
            q=run.q,
            v=run.v,
            qdd=run.qdd,
            lam=run.lam,
            status=np.array(run.status()),
            # NaN (an event not reached) as JSON's NaN token, read back by json.loads.
            events=np.array(events_text),
            key=np.array(cache_key),
            digest=np.array(digest([np.asarray(getattr(run, k)) for k in ARRAYS], events_text)),
        )
    except OSError:
        pass
