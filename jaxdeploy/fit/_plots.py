"""Figures of a fit: data against the model at the initial guess and at the estimate, with
residuals in noise units, and the loss history."""

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
        ax.set_ylabel(name)
        ax.legend(loc="best", fontsize=8)
        axr.plot(cmp_.times, (final - data) / cmp_.scale[name], ".", ms=2.5, color="tab:blue")
        axr.axhline(0.0, color="k", lw=0.6)
        axr.set_ylabel("residual / σ")
        axr.set_xlabel("t [s]")
        fig.tight_layout()
        files.append(save(fig, f"fit_{name}.png"))
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
    ax.set_ylabel("½ Σ r² (noise units)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    files.append(save(fig, "loss_history.png"))
    return files
