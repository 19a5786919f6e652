"""Writing a work–precision run: CSV, markdown table, PNG plot, JSON metadata (atomically)."""

from __future__ import annotations

import csv
import io
import os

import numpy as np

from ..io import atomic_write_bytes, atomic_write_json, machine_description, run_metadata
from .work_precision import Row, rows_as_dicts


def markdown_table(rows: list[Row]) -> str:
    header = (
        "| configuration | setting | error (window) | error (full) | wall [s] | compile [s] "
        "| steps | rejected | Newton it. | peak RSS [MB] | status |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for r in rows:
        lines.append(
            f"| {r.family} | {r.label} | {r.error_window:.2e} | {r.error_full:.2e} "
            f"| {r.wall_s:.3g} | {r.compile_s:.3g} | {r.steps if r.steps >= 0 else '–'} "
            f"| {r.rejected if r.rejected >= 0 else '–'} "
            f"| {r.newton_iterations if r.newton_iterations >= 0 else '–'} "
            f"| {r.peak_rss_mb:.0f} | {r.status} |"
        )
    return header + "\n".join(lines) + "\n"


ERROR_LEVELS = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8)


def fastest_per_error_level(rows: list[Row], levels=ERROR_LEVELS) -> str:
    """Markdown: for each error level (over the reference window), the fastest jaxdeploy
    configuration and the fastest peer (scipy, Exudyn) reaching it, and their wall-time
    ratio (issue 5's target: ≤ 1 at every level from 1e-3 to 1e-8)."""

    def fastest(level, ours):
        reach = [
            r
            for r in rows
            if r.status == "ok" and r.error_window <= level and (r.kind == "jaxdeploy") == ours
        ]
        return min(reach, key=lambda r: r.wall_s) if reach else None

    lines = [
        "| error level | fastest jaxdeploy | wall [s] | fastest peer | wall [s] | ours / peer |",
        "|---|---|---|---|---|---|",
    ]
    for level in levels:
        ours, peer = fastest(level, True), fastest(level, False)
        cells = []
        for r in (ours, peer):
            cells += (
                ["none reaches it", "–"]
                if r is None
                else [
                    f"{r.family} {r.label}",
                    f"{r.wall_s:.3g}",
                ]
            )
        ratio = "–" if ours is None or peer is None else f"{ours.wall_s / peer.wall_s:.2g}"
        lines.append(f"| {level:.0e} | " + " | ".join(cells) + f" | {ratio} |")
    return "\n".join(lines) + "\n"


def plot(rows: list[Row], path: str, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(13, 7), sharey=True)
    families = list(dict.fromkeys(r.family for r in rows))
    colors = plt.cm.tab20(np.linspace(0.0, 1.0, 20))  # 10 default colours repeat here
    markers = "os^vD<>ph*xP"
    for i, family in enumerate(families):
        sel = [r for r in rows if r.family == family and r.status == "ok"]
        if not sel:
            continue
        style = "--" if "scipy" in family else (":" if "Exudyn" in family else "-")
        for ax, attr in zip(axes, ("error_window", "error_full"), strict=True):
            ax.loglog(
                [getattr(r, attr) for r in sel],
                [r.wall_s for r in sel],
                style,
                marker=markers[i % len(markers)],
                label=family,
                ms=5,
                color=colors[i % len(colors)],
            )
    axes[0].set_xlabel("error over the reference window (max |e − e_ref| / c)")
    axes[1].set_xlabel("error over the full horizon")
    axes[0].set_ylabel("wall time per run [s] (median, compilation excluded)")
    for ax in axes:
        ax.grid(alpha=0.3, which="both")
        ax.invert_xaxis()
    fig.legend(*axes[0].get_legend_handles_labels(), loc="lower center", ncol=4, fontsize=7)
    fig.suptitle(title)
    fig.tight_layout(rect=(0, 0.16, 1, 1))
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=120)
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())


def write_report(out_dir: str, scene: str, reference, rows: list[Row], options: dict) -> list[str]:
    """Write `work_precision.csv`, `.md`, `.png` and `.json` into `out_dir`."""
    dicts = rows_as_dicts(rows)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(dicts[0]))
    writer.writeheader()
    writer.writerows(dicts)
    paths = {k: os.path.join(out_dir, f"work_precision.{k}") for k in ("csv", "md", "png", "json")}
    atomic_write_bytes(paths["csv"], buf.getvalue().encode())
    bound = reference.error_bound
    machine = machine_description()
    checks = "\n".join(
        f"* {e['solver']} at rtol {e['rtol']:g}"
        + (f", steps ≤ {e['dt_max']:g} s" if e.get("dt_max") else "")
        + f": {e['window']:.1e} over the window, {e['full']:.1e} over the full horizon"
        for e in reference.evidence
    )
    md = (
        f"Scene `{scene}`, horizon {reference.ts[-1]:.4g} s, {reference.ts.size} output times, "
        f"reference window t ≤ {reference.window_end:.4g} s. Reference: Dopri8 at rtol "
        f"{reference.rtol:g}; its differences to the check runs (relative eccentricity):\n\n"
        f"{checks}\n\nso its own error is at most {bound[0]:.1e} over the window and "
        f"{bound[1]:.1e} over the full horizon (the smallest difference). "
        f"Machine: {machine.get('Model name', '?')}, {machine.get('CPU(s)', '?')} CPUs, "
        f"load average {machine['load_average_1_5_15min'][0]:.1f} at the end of the run.\n\n"
        + markdown_table(rows)
        + "\nFastest configuration reaching each error level over the window (wall time "
        "per run, compilation excluded):\n\n" + fastest_per_error_level(rows)
    )
    atomic_write_bytes(paths["md"], md.encode())
    plot(rows, paths["png"], f"work–precision, {scene}")
    atomic_write_json(
        paths["json"],
        dict(
            scene=scene,
            options=options,
            reference=dict(
                rtol=reference.rtol,
                window_end=reference.window_end,
                t_end=float(reference.ts[-1]),
                n_save=int(reference.ts.size),
                evidence=reference.evidence,
                params=reference.params,
            ),
            machine=machine,
            rows=dicts,
            seed=None,  # a benchmark draws no random numbers: options and versions define it
            versions=run_metadata(),
        ),
    )
    return list(paths.values())
