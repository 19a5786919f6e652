"""The XLA compile options jaxdeploy chooses for a process that imports it.

A first call is mostly XLA compiling (docs/performance.md), and most of that is XLA:CPU
turning each of the program's ~500 fusions into machine code. XLA:CPU generates a fusion's
code in one of two ways: its MLIR fusion emitters (XLA's default since 2025) or its older
LLVM IR emitters, selected by `--xla_cpu_use_fusion_emitters` (`XLA_FLAGS=--help` lists it:
"Use fusion emitters for code generation in the CPU backend"). For jaxdeploy's programs the
older emitters compile faster and run no slower: the measurements are beside `DEFAULT_FLAGS`.

XLA reads `XLA_FLAGS` once, when JAX starts its backend (JAX's "XLA compiler flags" guide,
https://docs.jax.dev/en/latest/xla_flags.html: set it before any JAX computation). So the
flags are added to `os.environ["XLA_FLAGS"]` on `import jaxdeploy`, and only:

* when JAX's backend has not started yet (a script that ran a JAX computation before importing
  jaxdeploy keeps XLA's defaults: the flags would have no effect);
* for a flag the user has not set: a value of the same flag already in `XLA_FLAGS` wins;
* unless `JAXDEPLOY_XLA_FLAGS=off` was set before `import jaxdeploy`, which adds none.

Processes started from this one inherit the variable. The program cache keys its compiled
executables by `XLA_FLAGS` (`_program_cache._machine`) and JAX's compilation cache hashes
XLA's flags into its keys, so programs compiled under other flags are never mixed in.
"""

from __future__ import annotations

import os
import sys
import warnings

# `--xla_cpu_use_fusion_emitters=false`: XLA:CPU's LLVM IR emitters instead of its MLIR fusion
# emitters. Measured on the project's 2-core AMD EPYC (jax/jaxlib 0.10.2; one process per
# setting, compilation cache off; CPU seconds of the process: `jax.jit(f).lower(...)` then
# `.compile()` timed apart; load average 8-13 from other work, so single numbers vary by about
# ±25 %: the default's slider_crank compile measured 13.1 and 10.1 CPU-s in two processes):
#
#   program (scene defaults)          XLA compile CPU-s      warm run CPU-s    outputs
#                                     default -> this flag   default -> flag
#   slider_crank simulate             13.1, 10.1 -> 8.3, 7.5  0.24-0.67 both    bit-identical
#   deploy_array simulate (2 s)       18.4 -> 15.5            18.2 -> 10.7      see below
#   deploy_array reverse gradient     102.8 -> 91.4           3.4 -> 3.7        see below
#   (benchmarks/targets.gradient's loss, 0.2 s)
#
# Warm runs are within the load's noise (the same program varied 0.24-0.67 CPU-s). Other
# candidates, slider_crank's XLA compile CPU-s against the default's 10.1-13.1:
# `--xla_cpu_opt_preset=FAST_COMPILE` 11.1 (with this flag 10.6), `--xla_backend_optimization_
# level=2` 13.3 and `=1` 16.5 (LLVM's level: no gain), `--xla_cpu_parallel_codegen_split_count=1`
# 15.2; `--xla_backend_optimization_level=0` 12.3 but a different answer (1.3x the steps, slider
# moved 6.7 mm); `--xla_llvm_disable_expensive_passes=true` did not finish its compile in the
# time the others took.
#
# How deploy_array's outputs move: its saved q are bit-identical to 0.05 s and within 2e-13 to
# 0.2 s and 1e-9 up to the latch's lock at 0.54 s, where the run's own error is 3e-8 (the
# default run against one at rtol 1e-8, atol 1e-11). The lock's impacts then amplify every
# round-off difference to 1e-4..1e-3: after it the default run differs from the tighter one by
# 3.9e-4, from itself compiled for another instruction set (`--xla_cpu_max_isa=AVX`, a pure
# round-off change) by 1.3e-4, and from this flag's run by 7.0e-4 (max |Δq| over the 1001
# saved states, metres and radians). The gradient's components move by 1.6e-4 to 2.9e-4
# (relative), below its disagreement with central differences (docs/performance.md).
DEFAULT_FLAGS = ("--xla_cpu_use_fusion_emitters=false",)

# What `JAXDEPLOY_XLA_FLAGS` may say.
_OFF = ("off", "0", "false", "no", "none")
_ON = ("", "on", "1", "true", "yes", "default")
VARIABLE = "JAXDEPLOY_XLA_FLAGS"


def flag_name(token: str) -> str:
    """`--xla_foo=1` -> `--xla_foo`; a bare boolean flag is its own name."""
    return token.split("=", 1)[0]


def with_defaults(xla_flags: str, defaults=DEFAULT_FLAGS) -> str:
    """`xla_flags` (the value of `XLA_FLAGS`) with every flag of `defaults` whose name it does
    not already hold appended; the user's flags are kept as they were, in their order."""
    given = {flag_name(token) for token in xla_flags.split()}
    added = [flag for flag in defaults if flag_name(flag) not in given]
    return " ".join([xla_flags.strip(), *added]).strip()


def _backend_started() -> bool:
    """Whether JAX's backend has started in this process (XLA has then read its flags)."""
    bridge = sys.modules.get("jax._src.xla_bridge")
    if bridge is None:  # JAX not imported yet: nothing has started
        return False
    started = getattr(bridge, "backends_are_initialized", None)
    # A JAX without that function (a future version): add the flags; if the backend had
    # started they are without effect, as for any late change of XLA_FLAGS.
    return bool(started()) if started is not None else False


def apply_defaults(environ=os.environ) -> tuple[str, ...]:
    """Add `DEFAULT_FLAGS` to `environ["XLA_FLAGS"]` (see the module docstring for when).

    **Returns:** the flags added (empty when none was).
    """
    choice = environ.get(VARIABLE, "").strip().lower()
    if choice in _OFF:
        return ()
    if choice not in _ON:
        warnings.warn(
            f"{VARIABLE}={environ[VARIABLE]!r} is not understood (use 'off' to keep XLA's "
            "own defaults, or leave it unset); jaxdeploy's XLA flags are used",
            RuntimeWarning,
            stacklevel=3,
        )
    if _backend_started():
        return ()
    before = environ.get("XLA_FLAGS", "")
    after = with_defaults(before)
    if after == before.strip():
        return ()
    environ["XLA_FLAGS"] = after
    given = {flag_name(token) for token in before.split()}
    return tuple(flag for flag in DEFAULT_FLAGS if flag_name(flag) not in given)
