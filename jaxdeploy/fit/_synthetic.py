"""Synthetic measurements: a scene's channels at chosen times plus Gaussian noise."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from ._data import Measurements


def model_channels(scene, params: Mapping, ts, names: Sequence[str], **run_options) -> dict:
    """The channels `names` of `scene` run with `params` (complete or overrides), at `ts`."""
    from ..batch import run_scene

    params = scene.resolve_params(params)
    ts = np.asarray(ts, dtype=float)
    traj = run_scene(scene, params, float(ts[-1]), ts=ts, **run_options)
    if not traj.ok:
        raise RuntimeError(f"simulation of {scene.name} {traj.status()}")
    channels = scene.select_channels(scene.build(params), traj, names)
    return {n: np.asarray(v) for n, v in channels.items()}


def synthesize(
    scene,
    params: Mapping,
    ts,
    names: Sequence[str],
    *,
    noise_fraction: float = 0.01,
    seed: int = 0,
    **run_options,
) -> Measurements:
    """Noisy "measurements": each channel plus white Gaussian noise of standard deviation
    `noise_fraction` × the channel's RMS over `ts`; the noise levels are recorded."""
    clean = model_channels(scene, params, ts, names, **run_options)
    rng = np.random.default_rng(seed)
    channels, noise = {}, {}
    for n in names:
        sigma = noise_fraction * float(np.sqrt(np.mean(clean[n] ** 2)))
        if not sigma > 0:
            raise ValueError(f"channel {n!r} is identically zero over the times given")
        channels[n] = clean[n] + sigma * rng.standard_normal(clean[n].shape)
        noise[n] = sigma
    return Measurements(
        np.asarray(ts, dtype=float), channels, noise, source=f"synthetic:{scene.name}"
    )
