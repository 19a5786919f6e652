"""A result folder belongs to one run: taken with an exclusive lock, written as a fresh
folder beside it and moved into place when complete.

* **Lock.** `OutputFolder.claim` takes an exclusive `flock` on `.NAME.lock` beside the folder
  `NAME` (beside, not inside: the folder itself is replaced when the run ends) and records the
  holder (process id, host, command line, start time) in it. A second run into the same folder
  is refused at once, naming the holder. The kernel releases the lock when the process ends,
  however it ends, so a killed run never leaves the folder locked.
* **Staging.** A run writes into `.NAME.staging-PID` beside the folder; `commit` moves it to
  `NAME` (the older folder, with `--overwrite`, is first moved aside and then deleted). An
  `--overwrite` thus never leaves a file of the older run beside the new ones, and a run that
  dies leaves no half-written `NAME`: its staging folder is removed by `close` or, after a
  hard kill, by the next run that claims `NAME`.

Creating the lock file is also the test that the folder can be written at all: a read-only
place (`/proc/x`) is refused before any work.
"""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import socket
import sys
import time

from .io import check_output_dir

# Folders claimed by this process and not yet closed: `close_all` releases them when the
# process ends at once (Ctrl-C in the command line, which does not unwind).
_open: set = set()


def close_all() -> None:
    """Close every folder this process holds (remove uncommitted staging, release locks)."""
    for folder in list(_open):
        folder.close()


class FolderBusy(FileExistsError):
    """The output folder is held by another run."""


class OutputFolder:
    """The output folder `path` of one run (module docstring). `claim()` locks it (raising
    `FileExistsError` with a message for the user when it cannot), `staging` is where the
    run writes, `commit()` moves the result into place, `close()` removes what an
    uncommitted run wrote and releases the lock. Also a context manager: `with
    OutputFolder(...).claim() as folder:` closes on the way out."""

    def __init__(self, path: str, overwrite: bool = False):
        self.path = os.path.abspath(path)
        self.shown = path  # as the user gave it, for messages
        self.overwrite = overwrite
        parent, name = os.path.split(self.path)
        self.parent, self.name = parent, name
        self.lock_path = os.path.join(parent, f".{name}.lock")
        self.staging = os.path.join(parent, f".{name}.staging-{os.getpid()}")
        self._fd: int | None = None
        self.committed = False

    # --- plan -----------------------------------------------------------------------------

    def claim(self) -> OutputFolder:
        """Check the folder (`io.check_output_dir`), take its lock and create the staging
        folder. Raises `FileExistsError` (a message naming the folder, and the holder for
        `FolderBusy`)."""
        check_output_dir(self.shown, self.overwrite)
        if self.overwrite and os.path.isdir(self.path) and not os.access(self.path, os.W_OK):
            raise FileExistsError(
                f"--overwrite: output folder {self.shown!r} is not writable, so its files "
                "cannot be replaced; choose another --out"
            )
        try:
            os.makedirs(self.parent, exist_ok=True)
            self._lock()
            # Only a run holding the lock writes here: staging folders of runs that died
            # hard are leftovers.
            self._remove_leftovers()
            os.makedirs(self.staging)
        except FolderBusy:
            raise
        except OSError as err:
            self.close()
            raise FileExistsError(
                f"output folder {self.shown!r} cannot be written: {err.strerror or err}"
            ) from None
        return self

    def _lock(self) -> None:
        for _ in range(3):
            fd = os.open(self.lock_path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = _read_holder(fd)
                os.close(fd)
                raise FolderBusy(
                    f"output folder {self.shown!r} is in use by another run ({holder}); wait "
                    "for it to finish or choose another --out"
                ) from None
            # The holder before us may have removed the file between our open and our lock:
            # then we hold the lock of a file nobody else can see; open it afresh.
            try:
                same = os.stat(self.lock_path).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                self._fd = fd
                _open.add(self)
                holder = {
                    "pid": os.getpid(),
                    "host": socket.gethostname(),
                    "command": " ".join(sys.argv),
                    "started": time.strftime("%Y-%m-%d %H:%M:%S %Z"),
                }
                os.ftruncate(fd, 0)
                os.write(fd, json.dumps(holder).encode())
                return
            os.close(fd)
        raise FolderBusy(f"output folder {self.shown!r}: its lock keeps changing hands")

    def _remove_leftovers(self) -> None:
        prefix = f".{self.name}."
        for entry in os.listdir(self.parent):
            if entry.startswith(prefix) and (".staging-" in entry or ".old-" in entry):
                shutil.rmtree(os.path.join(self.parent, entry), ignore_errors=True)

    # --- write ----------------------------------------------------------------------------

    def file(self, name: str) -> str:
        """Where the run writes its file `name` (inside the staging folder)."""
        return os.path.join(self.staging, name)

    def commit(self) -> None:
        """Move the staging folder to `path`, replacing an older result (`--overwrite`)."""
        old = None
        if os.path.lexists(self.path):
            old = os.path.join(self.parent, f".{self.name}.old-{os.getpid()}")
            os.replace(self.path, old)
        os.replace(self.staging, self.path)
        self.committed = True
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)

    def close(self) -> None:
        """Remove the staging folder of an uncommitted run and release the lock."""
        if not self.committed:
            shutil.rmtree(self.staging, ignore_errors=True)
        if self._fd is not None:
            try:
                os.unlink(self.lock_path)
            except OSError:
                pass
            os.close(self._fd)  # releases the flock
            self._fd = None
        _open.discard(self)

    def __enter__(self) -> OutputFolder:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _read_holder(fd: int) -> str:
    """The holder recorded in a lock file, as words for a message."""
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        holder = json.loads(os.read(fd, 4096).decode() or "{}")
    except (OSError, ValueError):
        holder = {}
    if not holder:
        return "holder unknown"
    return (
        f"process {holder.get('pid')} on {holder.get('host')}, started "
        f"{holder.get('started')}: {holder.get('command')}"
    )


class FolderLock:
    """Only the lock of `OutputFolder`, for a result written in place (a sweep, resumable
    chunk by chunk): `FolderLock(path).claim()` raises `FolderBusy` naming the holder."""

    def __init__(self, path: str):
        self._folder = OutputFolder(path)
        self._folder.committed = True  # nothing staged: closing removes nothing

    def claim(self) -> FolderLock:
        folder = self._folder
        try:
            os.makedirs(folder.parent, exist_ok=True)
            folder._lock()
        except FolderBusy:
            raise
        except OSError as err:
            raise FileExistsError(
                f"output folder {folder.shown!r} cannot be written: {err.strerror or err}"
            ) from None
        return self

    def close(self) -> None:
        self._folder.close()

    def __enter__(self) -> FolderLock:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
