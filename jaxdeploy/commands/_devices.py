"""How many JAX CPU devices a batching command splits the machine into (`sweep`,
`optimize`): one per usable core by default, so that a batch's shards run side by side.

JAX reads the count when its backend starts (`jax_num_cpu_devices`), so only a process that
has not run JAX yet can choose it. Where the environment already fixes the count
(`XLA_FLAGS=--xla_force_host_platform_device_count`, `JAX_NUM_CPU_DEVICES`) or JAX has
started, the devices are left as they are, and an explicit `--devices` that they contradict
is refused (the message names why). The default applies to the command's own process only
(`_compilation_cache.is_command_line`): a script or a test that calls
`jaxdeploy.cli.main([...])` before it runs JAX itself would otherwise have all its later JAX
work split over the cores too.
"""

from __future__ import annotations

import os

from .._cores import usable_cores

DEVICES_HELP = (
    "CPU devices the batch is sharded over, one core each, ≥ 1 (default: one per core this "
    "process may use)"
)


def fixed_by_environment() -> str | None:
    """The environment setting that fixes JAX's CPU device count, or None."""
    if "xla_force_host_platform_device_count" in os.environ.get("XLA_FLAGS", ""):
        return "XLA_FLAGS=--xla_force_host_platform_device_count"
    if os.environ.get("JAX_NUM_CPU_DEVICES"):
        return "JAX_NUM_CPU_DEVICES"
    return None


def split_host(devices: int | None, default: int | None = None) -> str | None:
    """Ask JAX for `devices` CPU devices (`--devices`; None: `default`, else one per usable
    core, and only in the command's own process). **Returns:** a refusal naming why the
    request cannot hold, or None."""
    import jax

    from .._compilation_cache import is_command_line

    if devices is None and not is_command_line():
        return None
    fixed = fixed_by_environment()
    if fixed is not None:
        if devices is not None:
            return f"--devices {devices}: {fixed} already sets the number of CPU devices"
        return None
    wanted = devices or default or usable_cores()
    try:
        jax.config.update("jax_num_cpu_devices", wanted)
    except RuntimeError:  # JAX's backend runs already: its devices stay
        if devices is not None and devices != jax.device_count():
            return (
                f"--devices {devices}: JAX already runs in this process with "
                f"{jax.device_count()} device(s); run the command in a new process"
            )
    return None
