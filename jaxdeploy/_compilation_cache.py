"""A persistent XLA compilation cache for the command line.

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
"""

from __future__ import annotations

import os


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
    it; returns the compilation cache's folder.

    Leaves a cache directory the user configured for JAX itself untouched. A cache that
    cannot be created (read-only home) is skipped: compiling again is slower, not wrong.
    """
    import jax

    from . import _program_cache

    chosen = cache_dir()
    _program_cache.enable(None if chosen is None else chosen.rstrip(os.sep) + "-programs")
    if jax.config.jax_compilation_cache_dir:
        return jax.config.jax_compilation_cache_dir
    folder = cache_dir()
    if folder is None:
        return None
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError:
        return None
    jax.config.update("jax_compilation_cache_dir", folder)
    # JAX stores only programs that took ≥ 1 s to compile (its default); a warm run would
    # compile the small ones again each time (the scene build's array operations, the
    # contact histories: ~20 programs, about a second). Unless the user chose a threshold.
    if "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS" not in os.environ:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    return folder
