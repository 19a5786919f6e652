"""Figures of a fit: data against the model at the initial guess and at the estimate, with
residuals in noise units; the residuals against time and their autocorrelation (the whiteness
test of `_adequacy`); the loss history."""

from __future__ import annotations

import os

import numpy as np


def plot_fit(result, out_dir: str) -> list[str]:
    """Write `fit_<channel>.png` per channel and `loss_history.png`; return the file names."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io import atomic_savefig

    def save(fig, name):
        atomic_savefig(fig, os.path.join(out_dir, name), dpi=110)
        plt.close(fig)
        return name

    files = []
    cmp_ = result.comparison
    # The model where LM started (the guess, or the best point of a multistart), on the
    # first stage's residuals (e.g. smoothed channels).
    first_spec = (result.comparison_initial or cmp_).spec
    start_label = "start of the fit" + (
        f" (smoothed over {first_spec.width * 1e3:g} ms)" if first_spec.kind == "smooth"
        else f" ({first_spec.block * 1e3:g} ms block means)" if first_spec.kind == "block"
        else ""
    )  # fmt: skip
    for name in cmp_.names:
        data = cmp_.data_features[name]
        first = result.comparison_initial or cmp_  # the initial model ran on the first stage
        initial = first.features_np(result.model_initial[name])
        final = cmp_.features_np(result.model_final[name])
        fig, (ax, axr) = plt.subplots(
            2, 1, figsize=(8, 5.5), sharex=True, gridspec_kw={"height_ratios": [3, 1]}
        )
        ax.plot(cmp_.times, data, ".", ms=2.5, color="0.4", label="data")
        ax.plot(first.times, initial, "-", lw=1, color="tab:orange", label=start_label)
        ax.plot(cmp_.times, final, "-", lw=1.2, color="tab:blue", label="fitted")
        ax.set_ylabel(f"{name} [{channel_unit(name)}]")
        ax.legend(loc="best", fontsize=8)
        axr.plot(cmp_.times, (final - data) / cmp_.scale[name], ".", ms=2.5, color="tab:blue")
        axr.axhline(0.0, color="k", lw=0.6)
        axr.set_ylabel("residual / σ [-]")
        axr.set_xlabel("t [s]")
        fig.tight_layout()
        files.append(save(fig, f"fit_{name}.png"))
    files += plot_residuals(result, out_dir, plt, save)
    fig, ax = plt.subplots(figsize=(6, 3.5))
    it = np.arange(len(result.history))
    cost = np.array([h["cost"] for h in result.history])
    ok = np.array([h["accepted"] for h in result.history])
    ax.semilogy(it[ok], cost[ok], "o-", ms=3, label="accepted")
    if (~ok).any():
        ax.semilogy(
            it[~ok],
            np.where(np.isfinite(cost[~ok]), cost[~ok], np.nan),
            "x",
            color="tab:red",
            label="rejected trial",
        )
    ax.set_xlabel("evaluation")
    ax.set_ylabel("½ Σ r² [noise units²]")
    ax.legend(fontsize=8)
    fig.tight_layout()
    files.append(save(fig, "loss_history.png"))
    return files


def plot_residuals(result, out_dir, plt, save) -> list[str]:
    """`residuals.png` (residual/σ against time per channel, with the ±2 band of the stated
    noise) and `residual_autocorrelation.png` (sample autocorrelation per channel with the
    ±2/√n band of white noise, and the Ljung–Box verdict in the title)."""
    cmp_ = result.comparison
    r = cmp_.residuals_np(result.model_final)
    labels = np.asarray(cmp_.labels)
    verdict = "adequate" if result.adequate else "NOT ADEQUATE"
    n_ch = len(cmp_.names)
    fig, axes = plt.subplots(n_ch, 1, figsize=(8, 2.4 * n_ch + 0.6), sharex=True, squeeze=False)
    for ax, name in zip(axes[:, 0], cmp_.names, strict=True):
        ax.plot(cmp_.times, r[labels == name], ".", ms=2.5, color="tab:blue")
        ax.axhline(0.0, color="k", lw=0.6)
        for y in (-2.0, 2.0):
            ax.axhline(y, color="tab:red", lw=0.6, ls="--")
        ax.set_ylabel(f"{name}: residual / σ")
    axes[-1, 0].set_xlabel("t [s]")
    fig.suptitle(
        f"χ²/dof = {result.reduced_chi2:.3g} ({verdict}); dashed: ±2 stated noise", fontsize=9
    )
    fig.tight_layout()
    files = [save(fig, "residuals.png")]
    fig, axes = plt.subplots(n_ch, 1, figsize=(7, 2.4 * n_ch + 0.6), squeeze=False)
    for ax, name in zip(axes[:, 0], cmp_.names, strict=True):
        w = result.adequacy["whiteness"][name]
        rho = np.asarray(w["autocorrelation"])
        lags = np.arange(rho.size)
        ax.vlines(lags[1:], 0.0, rho[1:], color="tab:blue")
        ax.plot(lags[1:], rho[1:], "o", ms=3, color="tab:blue")
        band = 2.0 / np.sqrt(w["n"])
        ax.axhspan(-band, band, color="0.85")
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_ylabel(f"{name}: ρ̂(lag)")
        ax.set_title(
            f"Ljung–Box Q = {w['Q']:.3g} over {w['lags']} lags, p = {w['p_value_corrected']:.2g}"
            + (" (white)" if w["white"] else " (NOT white)"),
            fontsize=9,
        )
    axes[-1, 0].set_xlabel("lag [residuals]  (grey: ±2/√n, white noise)")
    fig.tight_layout()
    files.append(save(fig, "residual_autocorrelation.png"))
    return files


# Units of the scenes' channel names by their suffix (`Scene.channels`: `{body}_x`, `_y` in m,
# `_theta` in rad, `_ax`, `_ay` in m/s², `_atheta` in rad/s²; deploy_array's `alpha` in rad).
_CHANNEL_UNITS = (
    ("_atheta", "rad/s²"),
    ("_ax", "m/s²"),
    ("_ay", "m/s²"),
    ("_theta", "rad"),
    ("_x", "m"),
    ("_y", "m"),
)


def channel_unit(name: str) -> str:
    """The unit of channel `name`, from its suffix ("?" when the name does not say)."""
    if name == "alpha":
        return "rad"
    for suffix, unit in _CHANNEL_UNITS:
        if name.endswith(suffix):
            return unit
    return "?"
