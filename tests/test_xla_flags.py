"""jaxdeploy's XLA flags (`jaxdeploy/_xla_flags.py`): added on `import jaxdeploy` only while
JAX's backend has not started, never over a flag the user set, never with
`JAXDEPLOY_XLA_FLAGS=off`; and in effect: XLA compiles by them. Checked in new processes
(XLA reads its flags once per process), by what XLA compiled, never by time."""

import json
import os
import subprocess
import sys

import pytest

from jaxdeploy import _xla_flags
from jaxdeploy._xla_flags import DEFAULT_FLAGS, apply_defaults, with_defaults

FUSION_EMITTERS = "--xla_cpu_use_fusion_emitters"

# A new process: optionally run a JAX computation first (the backend starts), import jaxdeploy,
# then compile a sum. XLA:CPU's MLIR fusion emitters wrap a lone reduction in a fusion
# (`wrapped_reduce = ... fusion(...)`); its LLVM IR emitters, chosen by
# `--xla_cpu_use_fusion_emitters=false`, compile it as a bare `reduce` (jax 0.10.2).
_SCRIPT = """
import json, os, sys
import jax, jax.numpy as jnp
if sys.argv[1] == "backend-first":
    jnp.zeros(2).block_until_ready()
import jaxdeploy
text = jax.jit(jnp.sum).lower(jnp.ones(8)).compile().as_text()
root = [line for line in text.splitlines() if line.lstrip().startswith("ROOT")][-1]
print(json.dumps({"xla_flags": os.environ.get("XLA_FLAGS"), "root": root}))
"""


def _new_process(mode="import-first", **env_changes):
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", _xla_flags.VARIABLE)}
    env.update(env_changes)
    proc = subprocess.run(
        [sys.executable, "-c", _SCRIPT, mode], env=env, capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    out["fused"] = " fusion(" in out["root"]
    return out


def test_the_default_is_xla_cpu_llvm_ir_emitters():
    # What the module docstring and the measurements describe.
    assert DEFAULT_FLAGS == (f"{FUSION_EMITTERS}=false",)


def test_importing_jaxdeploy_puts_its_flags_in_effect():
    out = _new_process()
    assert out["xla_flags"] == f"{FUSION_EMITTERS}=false", out
    assert not out["fused"], out["root"]


def test_off_and_a_users_own_value_keep_xlas_default():
    # The negative control of the test above: the same probe, XLA's default emitters.
    off = _new_process(**{_xla_flags.VARIABLE: "off"})
    assert off["xla_flags"] is None and off["fused"], off
    own = _new_process(XLA_FLAGS=f"--xla_cpu_enable_fast_min_max=true {FUSION_EMITTERS}=true")
    assert own["xla_flags"] == f"--xla_cpu_enable_fast_min_max=true {FUSION_EMITTERS}=true"
    assert own["fused"], own


def test_other_user_flags_are_kept_and_ours_added():
    out = _new_process(XLA_FLAGS="--xla_force_host_platform_device_count=2")
    assert out["xla_flags"] == (
        f"--xla_force_host_platform_device_count=2 {FUSION_EMITTERS}=false"
    ), out
    assert not out["fused"], out["root"]


def test_nothing_is_added_once_the_backend_has_started():
    out = _new_process("backend-first")
    assert out["xla_flags"] is None and out["fused"], out


@pytest.mark.parametrize(
    "before, after",
    [
        ("", f"{FUSION_EMITTERS}=false"),
        ("  ", f"{FUSION_EMITTERS}=false"),
        (f"{FUSION_EMITTERS}=true", f"{FUSION_EMITTERS}=true"),
        (f"{FUSION_EMITTERS}", f"{FUSION_EMITTERS}"),  # a bare boolean flag is a value too
        ("--a=1 --b", f"--a=1 --b {FUSION_EMITTERS}=false"),
        # a longer flag that begins with the name is another flag
        (f"{FUSION_EMITTERS}_x=1", f"{FUSION_EMITTERS}_x=1 {FUSION_EMITTERS}=false"),
    ],
)
def test_with_defaults_adds_only_what_the_user_did_not_set(before, after):
    assert with_defaults(before) == after


def test_apply_defaults_reports_what_it_added_and_reads_the_switch(monkeypatch):
    monkeypatch.setattr(_xla_flags, "_backend_started", lambda: False)  # this process's has
    environ = {}
    assert apply_defaults(environ) == DEFAULT_FLAGS
    assert environ["XLA_FLAGS"] == " ".join(DEFAULT_FLAGS)
    assert apply_defaults(environ) == ()  # already there
    for off in ("off", "OFF", "0", "false", "none"):
        environ = {_xla_flags.VARIABLE: off}
        assert apply_defaults(environ) == () and "XLA_FLAGS" not in environ
    environ = {_xla_flags.VARIABLE: "sometimes"}
    with pytest.warns(RuntimeWarning, match="JAXDEPLOY_XLA_FLAGS='sometimes' is not understood"):
        assert apply_defaults(environ) == DEFAULT_FLAGS
