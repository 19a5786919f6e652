"""Compiled programs read ahead: a process that runs what an earlier one ran loads their kept
executables in a background thread while it imports, validates and builds.

With the caches filled, a process no longer traces or compiles (`_program_cache`), but it
still reads each compiled program back from the disk (`_program_cache._executable`): XLA
parses the program's HLO module, its buffer assignment and its object code, 0.4–0.8 s for
slider_crank's integration (a 3.7 MB executable of 10,900 HLO instructions), in series with
everything else the process does. The read releases Python's GIL, so it can overlap the
imports of diffrax and the scenes and the scene's build on the machine's other core.

What to read is known only once the programs' keys are, after the build. So each process that
asks for it (`start(name)`: the command line's `simulate`, a script's `enable_caches()`)
remembers, under its `name` (a command and the settings that choose its programs; a script's
path), the executables it ran, in order (a hint, written when the process ends); the next
process of that name starts reading them at once. A wrong hint costs the other core's time
and some memory, never a result: an executable read ahead is the file `_program_cache` would
read itself, used only for the entry it belongs to (its file name is the entry's key and the
machine's), and a program whose executable was not read ahead is read as before.

A hint records what it is for (`name`) and a digest of its list; one that does not match, is
damaged or names something other than an executable of the folder is discarded with one line
and rewritten by the process. It is kept in the program cache's folder and, like its entries,
is not read from a folder other users could write into.
"""

from __future__ import annotations

import atexit
import concurrent.futures
import hashlib
import json
import os
import re
import threading

from . import _program_cache

SUFFIX = ".ahead.json"
_EXECUTABLE = re.compile(r"^[0-9a-f]{64}-[0-9a-f]{16}\.executable$")
_started: set[str] = set()


def hint_path(folder: str, name: str) -> str:
    return os.path.join(folder, hashlib.sha256(name.encode()).hexdigest()[:32] + SUFFIX)


def _digest(name: str, executables: list) -> str:
    return hashlib.sha256(json.dumps([name, executables]).encode()).hexdigest()


def _is_entry(entry) -> bool:
    """`[file name, calls LAPACK]`, the name a kept executable's (no path: the folder's)."""
    return isinstance(entry, list) and len(entry) == 2 and bool(_EXECUTABLE.match(str(entry[0])))


def read_hint(path: str, name: str) -> list | None:
    """The `[file name, calls LAPACK]` pairs of the hint at `path`, None when there is none;
    a hint for another name, damaged or naming anything but executables is discarded."""
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read()
    except OSError:
        return None
    try:
        stored = json.loads(text)
        executables = stored["executables"]
        if stored.get("for") != name:
            why = "it was written for another process (its recorded name differs)"
        elif stored.get("digest") != _digest(name, executables):
            why = "its list does not match its digest"
        elif not all(_is_entry(e) for e in executables):
            why = "it names files that are not kept executables"
        else:
            return [(str(base), bool(lapack)) for base, lapack in executables]
    except (ValueError, KeyError, TypeError) as err:
        why = f"it cannot be read ({type(err).__name__})"
    return _program_cache.discard_entry(path, "program cache", why, "reading nothing ahead")


def start(name: str) -> None:
    """Read ahead, in a background thread, the executables the last process of this `name`
    ran, and remember this process's for the next (module docstring). Nothing when the
    program cache is off or its folder is not private; once per name and process."""
    folder = _program_cache.folder()
    if folder is None or name in _started:
        return
    if not _program_cache.folder_is_private(folder, "program cache"):
        return
    _started.add(name)
    path = hint_path(folder, name)
    hint = read_hint(path, name)
    atexit.register(_remember, folder, path, name, hint)
    if hint:
        # Every future is handed out before the thread starts: a program the process needs
        # before its turn waits for it (the hint's order is the order of use).
        futures = {os.path.join(folder, base): concurrent.futures.Future() for base, _ in hint}
        for where, future in futures.items():
            _program_cache.reading_ahead(where, future)
        stop = threading.Event()
        thread = threading.Thread(
            target=_read, args=(hint, futures, stop), name="read-ahead", daemon=True
        )
        thread.start()
        # At exit (after a refusal, say) the thread stops before its next file and is waited
        # for: an interpreter that shuts down while XLA still reads into it can crash.
        atexit.register(_finish, stop, thread)


def _finish(stop, thread) -> None:
    stop.set()
    thread.join()


def _read(hint, futures, stop) -> None:
    """Read each executable of `hint` into its future (None: not read, e.g. another machine's
    file, a process of several devices, or one that cannot be loaded: the program cache then
    reads or compiles it itself, and says why)."""
    machine = None
    try:
        import jax

        if jax.device_count() == 1:  # as `_program_cache._executable` keeps them
            machine = _program_cache.machine()
            if any(lapack for _, lapack in hint):
                _program_cache.prepare_lapack()
    except Exception:  # noqa: BLE001 - reading ahead is an optimisation only
        machine = None
    for where, future in futures.items():
        loaded = None
        if machine and not stop.is_set() and where.endswith(f"-{machine}.executable"):
            try:
                loaded = _program_cache.load_executable_quietly(where)
            except Exception:  # noqa: BLE001
                loaded = None
        future.set_result(loaded)


def _remember(folder, path, name, hint) -> None:
    """Write the hint of this process: its kept executables in the order it first ran them
    (at exit; unchanged hints are not rewritten)."""
    used = [
        [os.path.basename(where), lapack]
        for where, lapack in _program_cache.executables_run().items()
        if os.path.dirname(where) == folder and os.path.exists(where)
    ]
    if not used or [tuple(e) for e in used] == hint:
        return
    record = {"for": name, "executables": used, "digest": _digest(name, used)}
    _program_cache.store_file(path, json.dumps(record).encode())
