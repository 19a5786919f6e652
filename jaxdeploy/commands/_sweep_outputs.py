"""What `jaxdeploy sweep` writes beside its chunks: every finished case's features as a table
(`features.csv`, `features.json`) and an overview figure (`overview.png`).

The features of a case are its swept parameters, the design objective and its terms (with
`--objective`), and the quantities `jaxdeploy simulate` would put in the case's summary.json
(status, steps, the scene's summary: docs/results.md), each with its unit. Both files are
strict: JSON `null` and an empty CSV cell where a value is missing or not a finite number.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os

import numpy as np

from ..io import atomic_savefig, atomic_write_bytes, atomic_write_json
from ._results import describe_key

# Units of the objectives' features (jaxdeploy.objectives.FEATURES), by the signal they read.
_SIGNAL_UNITS = {"displacement": "m", "acceleration": "m/s²"}
_OBJECTIVE_UNITS = {
    "log_decay": "-",
    "settling_time": "s",
    "dominant_frequency": "Hz",
    "peak_contact_force": "N",
}
_DEFAULT_SIGNAL = {"peak_vibration": "displacement", "deployment_deviation": "displacement"}


def objective_unit(label: str) -> str:
    """Unit of an objective part labelled `panel:feature` or `panel:feature[signal]`
    (`objectives.Term.label`); the objective itself is a weighted sum of logarithms: "-"."""
    if label == "objective":
        return "-"
    feature = label.split(":", 1)[-1]
    signal = None
    if feature.endswith("]") and "[" in feature:
        feature, signal = feature[:-1].split("[", 1)
    if feature in _OBJECTIVE_UNITS:
        return _OBJECTIVE_UNITS[feature]
    return _SIGNAL_UNITS.get(signal or _DEFAULT_SIGNAL.get(feature, ""), "?")


def _value(value):
    """A JSON-ready scalar: NumPy numbers as Python numbers, NaN and infinities as None."""
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def feature_table(scene, data: dict, swept) -> tuple[list[str], dict[str, str], list[dict]]:
    """`(columns, units, rows)` of the finished cases in `data` (`sweep.load_sweep`): the case
    index, the `swept` parameters, the compiled features (`feature_*`) and the per-case
    summaries (`summary`, strict JSON per case), one row per case in case order."""
    columns = ["case", *swept]
    units = {"case": "-", **{name: scene.params[name].unit or "-" for name in swept}}
    features = [k[len("feature_") :] for k in data if k.startswith("feature_")]
    for name in features:
        columns.append(name)
        units[name] = objective_unit(name)
    summaries = [json.loads(text) for text in data.get("summary", [])]
    for summary in summaries:
        for key in summary:
            if key not in units:
                columns.append(key)
                found = describe_key(key)
                units[key] = "?" if found is None else (found[0] or "")
    rows = []
    for i, case in enumerate(data["case"]):
        row = {"case": int(case), **{name: _value(data[f"param_{name}"][i]) for name in swept}}
        row.update({name: _value(data[f"feature_{name}"][i]) for name in features})
        if summaries:
            row.update({key: _value(summaries[i].get(key)) for key in columns if key not in row})
        rows.append(row)
    return columns, units, rows


def write_features(out_dir: str, scene, data: dict, swept) -> list[str]:
    """Write `features.csv` (header `name [unit]`) and `features.json` (`units`, `columns`,
    `cases`) for the finished cases; returns their paths."""
    columns, units, rows = feature_table(scene, data, swept)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow([f"{c} [{units[c]}]" if units[c] else c for c in columns])
    for row in rows:
        writer.writerow(["" if row.get(c) is None else row[c] for c in columns])
    csv_path = os.path.join(out_dir, "features.csv")
    json_path = os.path.join(out_dir, "features.json")
    atomic_write_bytes(csv_path, buffer.getvalue().encode())
    atomic_write_json(
        json_path,
        {
            "scene": scene.name,
            "swept": list(swept),
            "columns": columns,
            "units": units,
            "cases": rows,
        },
    )
    return [csv_path, json_path]


def plot_overview(out_dir: str, scene, data: dict, swept, grid) -> tuple[str | None, int]:
    """Write `overview.png` (`overview_figure`); returns its path (None when there is nothing
    to plot) and the number of cases left out of it (failed or implausible)."""
    fig, left_out = overview_figure(scene, data, swept, grid)
    if fig is None:
        return None, left_out
    import matplotlib.pyplot as plt

    path = os.path.join(out_dir, "overview.png")
    atomic_savefig(fig, path, dpi=110)
    plt.close(fig)
    return path, left_out


def plotted(rows: list[dict]) -> list[dict]:
    """The rows an overview plots: cases whose status is "ok" (a failed case's numbers are
    null, an implausible one's are numbers the physics does not allow). Rows without a
    status (a sweep without summaries) are all plotted."""
    return [r for r in rows if r.get("status", "ok") == "ok"]


def overview_figure(scene, data: dict, swept, grid):
    """`(figure, left_out)`: each numeric feature against the first swept parameter, one
    line per combination of the others, axes labelled with units, of the cases `plotted`
    (None when none is); `left_out` counts the others, and the title says so."""
    columns, units, rows = feature_table(scene, data, swept)
    kept = plotted(rows)
    left_out = len(rows) - len(kept)
    rows = kept
    if not rows:
        return None, left_out
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    numeric = [
        c
        for c in columns[1 + len(swept) :]
        if all(isinstance(r.get(c), int | float | type(None)) for r in rows)
        and any(isinstance(r.get(c), int | float) for r in rows)
    ]
    if not numeric:
        return None, left_out
    x_name, others = swept[0], list(swept[1:])
    x = np.array([r[x_name] for r in rows], dtype=float)
    groups: dict[tuple, list[int]] = {}
    for i, r in enumerate(rows):
        groups.setdefault(tuple(r[o] for o in others), []).append(i)
    n_cols = min(4, len(numeric))
    n_rows = math.ceil(len(numeric) / n_cols)
    fig, axes = plt.subplots(n_rows, n_cols, figsize=(3.6 * n_cols, 2.6 * n_rows), squeeze=False)
    # A geometric grid (all values positive over a decade or more) reads best on a log axis.
    values = np.asarray(grid[x_name], dtype=float)
    log_x = bool(np.all(values > 0) and values.max() >= 10 * values.min())
    for ax, name in zip(axes.flat, numeric, strict=False):
        y = np.array([np.nan if r.get(name) is None else r[name] for r in rows], dtype=float)
        for key, members in groups.items():
            order = sorted(members, key=lambda i: x[i])
            label = ", ".join(f"{o} = {v:g} {units[o]}" for o, v in zip(others, key, strict=True))
            ax.plot(x[order], y[order], "o-", ms=3, lw=1, label=label or None)
        if log_x:
            ax.set_xscale("log")
        else:  # SI values such as a clearance of 1e-4 m: powers of ten, not 0.00010 labels
            ax.ticklabel_format(axis="x", style="sci", scilimits=(-3, 4), useOffset=False)
            ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(5))
        ax.set_xlabel(f"{x_name} [{units[x_name]}]", fontsize=8)
        ax.set_ylabel(f"{name} [{units[name] or '-'}]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(numeric) :]:
        ax.set_visible(False)
    if others:
        axes.flat[0].legend(fontsize=6)
    title = f"sweep of {scene.name}: {len(rows)} cases"
    if left_out:
        title += f" ({left_out} failed or implausible, not shown: features.csv)"
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig, left_out
