"""jaxdeploy's two persistent caches: JAX's compilation cache and the program cache.

Compiling the default deploy_array simulation takes seconds to tens of seconds on a small CPU;
with JAX's persistent cache (https://docs.jax.dev/en/latest/persistent_compilation_cache.html)
a second `jaxdeploy simulate` with the same scene composition loads the compiled program
instead. Parameter values are data, so changing `--set` values does not miss the cache;
changing what is composed (e.g. friction exactly 0) compiles once more.

JAX does not store programs that contain host callbacks. Equinox's runtime checks
(`eqx.error_if`, which diffrax uses to check `dt0`'s sign and that `SaveAt.ts` is sorted and
inside [t0, t1]) are host callbacks unless `EQX_ON_ERROR` is `nan` or `off`. The command line
therefore sets `EQX_ON_ERROR=nan` (unless the user set it) before equinox is imported, and
`simulate` checks those same conditions in Python before tracing, so they cannot fire.

The persistent cache skips only XLA's backend compile; `_program_cache` keeps the traced
and lowered programs beside it (folder + `-programs`), so that a warm run skips tracing too.

Location: `$JAXDEPLOY_CACHE_DIR`, else `$XDG_CACHE_HOME/jaxdeploy/xla`, else
`~/.cache/jaxdeploy/xla`. Set `JAXDEPLOY_CACHE_DIR=off` to disable both.

Who turns them on: the command line, always (unless `off`); a Python script, with the public
`jaxdeploy.enable_caches()` or by setting `JAXDEPLOY_CACHE_DIR` before `import jaxdeploy`
(which then calls it). They stay off in Python otherwise: a library should not write to a
user's home unasked, and the caches switch equinox's runtime checks to NaNs (above).
"""

from __future__ import annotations

import os
import sys
import warnings


def cache_dir() -> str | None:
    chosen = os.environ.get("JAXDEPLOY_CACHE_DIR")
    if chosen is not None:
        return None if chosen.strip().lower() in ("", "off", "0", "none") else chosen
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "jaxdeploy", "xla")


def prefer_cacheable_errors() -> None:
    """Ask equinox for callback-free runtime checks (see the module docstring). Must run
    before equinox is imported to have an effect; does nothing when the cache is off or the
    user chose `EQX_ON_ERROR` themselves."""
    if cache_dir() is not None:
        os.environ.setdefault("EQX_ON_ERROR", "nan")


def enable_compilation_cache() -> str | None:
    """Point JAX's persistent compilation cache at `cache_dir()` and the program cache beside
    it (the command line's set-up, after `prefer_cacheable_errors`); returns the compilation
    cache's folder."""
    from . import _program_cache

    chosen = cache_dir()
    if chosen is None:
        import jax

        _program_cache.enable(None)
        return jax.config.jax_compilation_cache_dir or None
    return _enable(chosen)


def _enable(folder: str) -> str | None:
    """The compilation cache in `folder`, the program cache in `folder` + `-programs`.

    Leaves a cache directory the user configured for JAX itself untouched. A folder that
    cannot be created or written, or that other users could write into, is not used, with
    one line saying so (`usable_folder`): compiling again is slower, not wrong.
    """
    import jax

    from . import _program_cache

    programs = folder.rstrip(os.sep) + "-programs"
    _program_cache.enable(programs if usable_folder(programs, "program cache") else None)
    if jax.config.jax_compilation_cache_dir:
        return jax.config.jax_compilation_cache_dir
    if not usable_folder(folder, "compilation cache"):
        return None
    jax.config.update("jax_compilation_cache_dir", folder)
    _heal_damaged_entries()
    # JAX stores only programs that took ≥ 1 s to compile (its default); a warm run would
    # compile the small ones again each time (the scene build's array operations, the
    # contact histories: ~20 programs, about a second). Unless the user chose a threshold.
    if "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS" not in os.environ:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    return folder


_judged: dict[str, bool] = {}


def usable_folder(folder: str, cache: str) -> bool:
    """Whether `cache`'s `folder` may be used: created if missing (private: mode 0700), a
    folder, writable by this process, owned by its user and not writable by group or others.
    Entries of every cache are loaded as code or unpickled (compiled executables, pickled tree
    structures) or trusted as results (the reference runs), so a folder another user could
    write into is not read. A folder that cannot be used is reported once per process, with
    one line naming the cache, the reason and the remedy; the run goes on without that cache
    (slower, the same results)."""
    if folder in _judged:
        return _judged[folder]
    problem = folder_problem(folder)
    if problem is not None:
        print(
            f"warning: {cache}: not using {folder}: {problem}; running without it (slower, "
            "the same results)",
            file=sys.stderr,
        )
    _judged[folder] = problem is None
    return _judged[folder]


def folder_problem(folder: str) -> str | None:
    """Why `folder` cannot hold a cache (`usable_folder`), or None; creates it if missing."""
    try:
        os.makedirs(folder, mode=0o700, exist_ok=True)
        info = os.stat(folder)
    except OSError as err:
        return (
            f"it cannot be created ({err.strerror or type(err).__name__}); choose another "
            "JAXDEPLOY_CACHE_DIR, or set JAXDEPLOY_CACHE_DIR=off"
        )
    mode = f"mode {info.st_mode & 0o777:o}, owner uid {info.st_uid}"
    if hasattr(os, "getuid") and info.st_uid != os.getuid():
        return (
            f"it belongs to another user ({mode}) and its entries are loaded as code; choose "
            "another JAXDEPLOY_CACHE_DIR"
        )
    if info.st_mode & 0o022:
        return (
            f"it is writable by other users ({mode}) and its entries are loaded as code; run "
            f"`chmod go-w {folder}` or choose another JAXDEPLOY_CACHE_DIR"
        )
    if not os.access(folder, os.W_OK | os.X_OK):
        return (
            f"it is not writable ({mode}); run `chmod u+w {folder}` or choose another "
            "JAXDEPLOY_CACHE_DIR"
        )
    return None


def enable_caches(path: str | os.PathLike | None = None) -> str | None:
    """Turn on jaxdeploy's persistent caches for this process, as the command line does.

    Afterwards a `simulate` (and the initial state's assembly, `consistent_state`) whose
    mechanism has the composition, array shapes and settings of an earlier one, in this or
    any later process, reads its program back instead of tracing it (as does a fit's model,
    its channels and their Jacobian, for the same scene, fitted parameters, fixed values and
    step control: `jaxdeploy.fit._model_program`; a design problem's batch objective and
    pathwise gradient: `jaxdeploy._design_program`; and a sweep's vmapped chunk without
    features: `jaxdeploy.sweep._chunk_program`) (the program cache,
    `jax.export`: see `jaxdeploy/_program_cache.py` for what its key holds), and XLA loads
    the compiled program from JAX's persistent compilation cache instead of compiling it.
    Results are bit for bit those of an uncached run; new parameter values reuse the
    programs (they are data). A script run again also reads the compiled programs its last
    run ran in a background thread from this call on, while it builds (`_read_ahead`; named
    by the script's path, so not for `python -c` or an interactive session).

    **Arguments:** `path`: the compilation cache's folder; the program cache goes beside it
    in `path + "-programs"`. Default: `$JAXDEPLOY_CACHE_DIR`, else
    `$XDG_CACHE_HOME/jaxdeploy/xla`, else `~/.cache/jaxdeploy/xla` — the command line's, so
    a script and `jaxdeploy simulate` share them. `JAXDEPLOY_CACHE_DIR=off` turns both off.

    Call it first, before anything imports equinox or diffrax (`import jaxdeploy as jd;
    jd.enable_caches()` at the top of a script, or set `JAXDEPLOY_CACHE_DIR` before starting
    Python, which calls it on import): it sets `EQX_ON_ERROR=nan` (unless you chose a value),
    because JAX can neither export nor store a program whose runtime checks are host
    callbacks. `simulate` checks its inputs in Python first, so no check is lost there; in
    your own equinox code, `eqx.error_if` then gives NaN instead of raising. Called after
    equinox was imported with raising checks, it warns and turns on the compilation cache
    alone. A JAX compilation cache folder you configured yourself (`jax_compilation_cache_dir`)
    is kept.

    **Returns:** the compilation cache's folder, or None when the caches are off.
    """
    from . import _program_cache

    if path is not None:
        path = os.fspath(path)
        chosen = None if path.strip().lower() in ("", "off", "0", "none") else path
    else:
        chosen = cache_dir()
    if chosen is None:
        _program_cache.enable(None)
        return None
    if "equinox" not in sys.modules:
        os.environ.setdefault("EQX_ON_ERROR", "nan")
    elif _program_cache.equinox_on_error() not in ("nan", "off"):
        warnings.warn(
            "jaxdeploy.enable_caches(): equinox was imported before it, with runtime checks "
            "that are host callbacks (EQX_ON_ERROR=raise), so programs cannot be exported: "
            "only the compilation cache is on. Call enable_caches() before importing anything "
            "else, or set EQX_ON_ERROR=nan (or JAXDEPLOY_CACHE_DIR) before starting Python.",
            RuntimeWarning,
            stacklevel=2,
        )
    enabled = _enable(chosen)
    _read_ahead_for_script()
    return enabled


def _read_ahead_for_script() -> None:
    """A script run again reads the compiled programs its last run ran in a background thread
    while it goes on (`_read_ahead`, named by the script's path); nothing for an interactive
    session or `python -c`."""
    from . import _read_ahead

    script = sys.argv[0] if sys.argv else ""
    if script and os.path.isfile(script) and not is_command_line(script):
        _read_ahead.start("python " + os.path.abspath(script))


def is_command_line(script: str | None = None) -> bool:
    """Whether `script` (default: this process's, `sys.argv[0]`) is the `jaxdeploy` command
    (its console script, or `python -m jaxdeploy.cli`), not a Python program that imports or
    calls it. `JAXDEPLOY_CACHE_DIR` also reaches the command on import; its commands read
    ahead their own programs under their own names (`jaxdeploy simulate`); one name for every
    command would read a simulate's programs into a sweep, and the reading starts JAX's backend
    before `jaxdeploy sweep` can choose its devices."""
    if script is None:
        script = sys.argv[0] if sys.argv else ""
    here = os.path.dirname(os.path.abspath(__file__))
    name = os.path.splitext(os.path.basename(script))[0]  # the console script, any platform
    return name == "jaxdeploy" or os.path.abspath(script) == os.path.join(here, "cli.py")


def _heal_damaged_entries() -> None:
    """Make JAX's compilation cache drop an entry it cannot read, so that it is rewritten.

    JAX warns about an entry it cannot decompress or deserialize ("Error reading persistent
    compilation cache entry for 'NAME'"), compiles the program again, and then does not store
    it, because a file under its key exists: every later run pays the compile and the
    warnings again. JAX has no public hook for this; its warning is public behaviour, so it
    is caught here (`warnings.showwarning`): the cache's entries of that program's name
    (`NAME-KEY-cache`; the damaged one among them, and any other shapes of the same program,
    which are compiled and stored again once) are deleted with one line naming the cache and
    the remedy, and JAX's own write after the compile stores a good entry.
    """
    if getattr(warnings.showwarning, "_jaxdeploy_heals", False):
        return
    shown = warnings.showwarning

    def showwarning(message, category, filename, lineno, file=None, line=None):
        text = str(message)
        if text.startswith(_READ_ERROR):
            name = text[len(_READ_ERROR) :].split("'", 1)[0]
            if name and _discard(name, text):
                return
        shown(message, category, filename, lineno, file, line)

    showwarning._jaxdeploy_heals = True
    warnings.showwarning = showwarning


# The start of JAX's warning about an entry it cannot read (jax/_src/compiler.py), followed
# by the program's name and a quote.
_READ_ERROR = "Error reading persistent compilation cache entry for '"


def _discard(name: str, text: str) -> bool:
    """Delete the compilation cache's entries of program `name`; False when there are none
    (then JAX's warning is shown as it is)."""
    import glob

    import jax

    folder = jax.config.jax_compilation_cache_dir
    if not folder or os.sep in name:
        return False
    entries = glob.glob(os.path.join(glob.escape(folder), f"{glob.escape(name)}-*-cache"))
    if not entries:
        return False
    for path in entries:
        for doomed in (path, path[: -len("-cache")] + "-atime"):  # jax's file names
            try:
                os.unlink(doomed)
            except OSError:
                pass
    reason = text.split(": ", 1)[-1][:120]
    print(
        f"warning: compilation cache: discarding {len(entries)} entry(ies) of {name} in "
        f"{folder} that JAX could not read ({reason}); compiling again and rewriting them "
        "(if this recurs, delete the folder)",
        file=sys.stderr,
    )
    return True
