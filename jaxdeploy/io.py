"""Writing results so that a kill never leaves a half-written file, and a run records what
produced it (parameters, versions, the code's git revision)."""

from __future__ import annotations

import json
import math
import os
import platform
import subprocess
import sys
import tempfile

import numpy as np

from ._version import __version__

TEMP_PREFIX = ".tmp-"


def atomic_write_bytes(path: str, data: bytes) -> None:
    """Write to a temporary file in the same folder, fsync, then rename over `path`.

    A reader (or a crash at any moment) sees either the previous file or the complete new one:
    `os.replace` is atomic on POSIX within one file system. On an exception the temporary file
    is removed; after a hard kill (SIGKILL, power loss) a hidden `.tmp-*` file may remain, never
    a truncated `path`.
    """
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=TEMP_PREFIX, suffix=os.path.basename(path))
    try:
        # mkstemp creates the file private (0600); a result gets the mode `open` would give.
        os.fchmod(fd, 0o666 & ~_umask())
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    _fsync_folder(folder)


def _umask() -> int:
    # Read by setting and restoring it: the only portable way.
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _fsync_folder(folder: str) -> None:
    # Makes the rename itself durable; not every platform can open a folder.
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def atomic_savefig(fig, path: str, **kwargs) -> None:
    """`fig.savefig` through `atomic_write_bytes` (format from the file extension)."""
    import io

    buffer = io.BytesIO()
    fmt = os.path.splitext(path)[1].lstrip(".") or None
    fig.savefig(buffer, format=fmt, **kwargs)
    atomic_write_bytes(path, buffer.getvalue())


def _jsonable(value):
    """`value` as strict JSON data: arrays and numpy scalars as lists and numbers, a
    non-finite float (NaN, ±inf: no JSON number) as None."""
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if hasattr(value, "shape") or isinstance(value, np.generic):
        arr = np.asarray(value)
        return _jsonable(arr.item() if arr.ndim == 0 else arr.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def strict_json(obj, **options) -> str:
    """`obj` as strict JSON text (RFC 8259: null where a number is NaN or infinite, never the
    bare `NaN`/`Infinity` Python's json writes by default)."""
    return json.dumps(_jsonable(obj), allow_nan=False, **options)


def atomic_write_json(path: str, obj) -> None:
    """Write `obj` as strict JSON (`strict_json`), atomically."""
    atomic_write_bytes(path, (strict_json(obj, indent=2) + "\n").encode())


def atomic_write_npz(path: str, **arrays) -> None:
    import io

    buffer = io.BytesIO()
    np.savez_compressed(buffer, **{k: np.asarray(v) for k, v in arrays.items()})
    atomic_write_bytes(path, buffer.getvalue())


GIT_TIMEOUT = 5.0  # s; a hung git (network file system, lock) must not hold up a result


def _git(args, folder):
    """`git -C folder *args` stdout, or `None` if git is missing, fails or times out."""
    try:
        out = subprocess.run(
            ["git", "-C", folder, *args],
            capture_output=True,
            text=True,
            timeout=GIT_TIMEOUT,
            check=True,
            env={**os.environ, "GIT_OPTIONAL_LOCKS": "0"},  # `status` must not write the index
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout


def duration_text(seconds: float) -> str:
    """`seconds` in the largest unit that keeps the number ≥ 1 (days, hours, minutes, s)."""
    for unit, size in (("days", 86400.0), ("hours", 3600.0), ("minutes", 60.0)):
        if seconds >= size:
            return f"{seconds / size:.3g} {unit}"
    return f"{seconds:.3g} s"


# Paths of a checkout that its page generators write (`jaxdeploy.pages`): a change there is
# not a change of the code, for a page's provenance nor for a run's `code_revision`.
GENERATED = ("docs/", "README.md")


def changed_code(porcelain: str) -> bool:
    """Whether `git status --porcelain --untracked-files=no` output names a tracked file
    outside `GENERATED` (a rename counts by its new path, `git status`'s "old -> new")."""
    paths = (line[3:].split(" -> ")[-1].strip('"') for line in porcelain.splitlines())
    return any(path and not path.startswith(GENERATED) for path in paths)


def code_revision(package_dir: str | None = None) -> dict | None:
    """`{"commit": sha, "dirty": bool}` of the git checkout the package runs from, or `None`
    when it does not run from one (an installed wheel, no git, git failing or slower than
    `GIT_TIMEOUT`). The package counts as running from a checkout only if its own
    `__init__.py` is tracked there: a wheel installed into a virtual environment that lives
    inside some repository (`.venv` in a checkout) is not that repository's code. `dirty`:
    tracked files differ from the commit (untracked files, e.g. results, are not counted, nor
    are the generated pages, `GENERATED`: a page written beside a run does not change its code).

    **Arguments:**
    - `package_dir`: the package folder (default: this package's).
    """
    folder = package_dir or os.path.dirname(os.path.abspath(__file__))
    if _git(["ls-files", "--error-unmatch", "__init__.py"], folder) is None:
        return None
    commit = _git(["rev-parse", "HEAD"], folder)
    status = _git(["status", "--porcelain", "--untracked-files=no"], folder)
    if commit is None or status is None:
        return None
    return {"commit": commit.strip(), "dirty": changed_code(status)}


def run_metadata() -> dict:
    """Versions, machine and the code's git revision (`code_revision`), stored beside every
    result."""
    import diffrax
    import equinox
    import jax

    return {
        "jaxdeploy": __version__,
        "jax": jax.__version__,
        "diffrax": diffrax.__version__,
        "equinox": equinox.__version__,
        "numpy": np.__version__,
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "devices": [str(d) for d in jax.devices()],
        "git": code_revision(),
    }


def machine_description() -> dict:
    """CPU model, core count and load average at the time of the call (lscpu when
    available): beside every timing, so that a reader knows what the seconds were measured on
    and how loaded the machine was."""
    info = {"platform": platform.platform(), "python": platform.python_version()}
    try:
        lscpu = subprocess.run(["lscpu"], capture_output=True, text=True, timeout=10).stdout
        wanted = ("Model name", "CPU(s)", "Thread(s) per core", "L2 cache", "L3 cache")
        for line in lscpu.splitlines():
            key, _, value = line.partition(":")
            if key.strip() in wanted:
                info[key.strip()] = value.strip()
    except (OSError, subprocess.SubprocessError):
        pass
    info["load_average_1_5_15min"] = os.getloadavg()
    return info


def revision_label(revision: dict | None = None) -> str:
    """`commit abc1234567` (with `, uncommitted changes` when dirty) for a page or table that
    says which code made its numbers; `revision` as `code_revision` returns it (default: now)."""
    revision = code_revision() if revision is None else revision
    if not revision:
        return "a copy not in git"
    dirty = " (uncommitted changes)" if revision["dirty"] else ""
    return f"commit {revision['commit'][:10]}{dirty}"


def replace_block(path: str, name: str, text: str) -> None:
    """Replace the generated block `<!-- BEGIN name -->` … `<!-- END name -->` of the page at
    `path` with `text` (appended when the page has no such block; the page is created when
    missing), written atomically: the prose around it stays hand-written, the numbers inside
    come from the script that owns the block."""
    begin, end = f"<!-- BEGIN {name} -->", f"<!-- END {name} -->"
    page = ""
    if os.path.exists(path):
        with open(path, encoding="utf-8") as fh:
            page = fh.read()
    block = f"{begin}\n{text.rstrip()}\n{end}"
    if begin in page and end in page:
        head, rest = page.split(begin, 1)
        page = head + block + rest.split(end, 1)[1]
    else:
        page = page.rstrip() + "\n\n" + block + "\n"
    atomic_write_bytes(path, page.encode("utf-8"))


def check_output_dir(path: str, overwrite: bool) -> None:
    """Refuse (`FileExistsError`) a non-empty existing folder unless `overwrite`; a file in
    the way (the path itself or any folder above it) is refused too, and so is a path that
    cannot be created (no write permission, an empty or malformed name). Creates nothing, so
    it can run before any work is done."""
    if not isinstance(path, str) or not path.strip() or "\0" in path:
        raise FileExistsError(f"output path {path!r} is invalid: give a folder name")
    if os.path.exists(path) and not os.path.isdir(path):
        raise FileExistsError(f"output path {path!r} exists and is not a folder")
    # The nearest existing folder above `path` is where makedirs would start: it must be a
    # folder (not a file) we may write into.
    ancestor = os.path.dirname(os.path.abspath(path))
    while not os.path.exists(ancestor):
        ancestor = os.path.dirname(ancestor)
    if not os.path.isdir(ancestor):
        raise FileExistsError(
            f"output path {path!r} is invalid: {ancestor!r} above it is a file, not a folder"
        )
    if not os.path.isdir(path) and not os.access(ancestor, os.W_OK | os.X_OK):
        raise FileExistsError(f"output path {path!r} cannot be created: {ancestor!r} is read-only")
    if os.path.isdir(path) and _results_in(path) and not overwrite:
        raise FileExistsError(
            f"output folder {path!r} already holds results; pass --overwrite to replace them "
            "or choose another --out"
        )


def _is_partial_write(name: str) -> bool:
    """A temporary file of `atomic_write_bytes` left behind by a killed writer."""
    return name.startswith(TEMP_PREFIX)


def _results_in(path: str) -> list[str]:
    """Entries of `path` that are results (leftover partial writes are not)."""
    return [name for name in os.listdir(path) if not _is_partial_write(name)]


def prepare_output_dir(path: str, overwrite: bool) -> None:
    """Create `path`; refuse a non-empty existing folder unless `overwrite`. Partial writes
    left by a killed run (never results: the rename did not happen) are removed."""
    check_output_dir(path, overwrite)
    os.makedirs(path, exist_ok=True)
    for name in os.listdir(path):
        if _is_partial_write(name):
            os.remove(os.path.join(path, name))


def default_output_dir(command: str, label: str, root: str = "results") -> str:
    """A fresh folder name for a command's results when the user gives none:
    `results/COMMAND/LABEL-YYYYMMDD-HHMMSS` (local time), with `-2`, `-3`, ... appended if that
    exists already, so that runs of different commands, or of the same command one after
    another, never write into the same folder."""
    import time

    stamp = time.strftime("%Y%m%d-%H%M%S")
    base = os.path.join(root, command, f"{label}-{stamp}")
    path, n = base, 1
    while os.path.exists(path):
        n += 1
        path = f"{base}-{n}"
    return path
