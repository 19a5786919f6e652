"""Reference measurements: sampled channels of one run, read from CSV or npz, checked on entry.

A measurement file holds a time column (`t` or `time`, seconds, strictly increasing) and one
column per measured channel, named after the scene's outputs (`Scene.channels`, e.g.
`alpha`, `panel2_tip_ay`). An optional noise level (one standard deviation, in the channel's
unit) is given per channel (`sigma_<channel>`) or for all channels (`sigma`):

* CSV: a header row with the column names; noise levels on comment lines before it,
  `# sigma_alpha = 1e-4` or `# sigma = 0.01`.
* npz: arrays `t` (or `time`) and one per channel; scalar arrays `sigma_<channel>`/`sigma`.

Every problem found is reported as a `MeasurementError` naming the file, the column and, for
bad numbers, the row.
"""

from __future__ import annotations

import io
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

TIME_NAMES = ("t", "time")


class MeasurementError(ValueError):
    """A measurement file (or array set) that cannot be used, and why."""


@dataclass(frozen=True)
class Measurements:
    """Sampled reference channels.

    `t` (N,) [s], strictly increasing; `channels` `{name: (N,)}`; `noise` `{name: σ}` for
    the channels whose noise level is known (one standard deviation, channel units);
    `source` names where the data came from (for messages and reports).
    """

    t: np.ndarray
    channels: dict[str, np.ndarray]
    noise: dict[str, float] = field(default_factory=dict)
    source: str = "<arrays>"

    def __post_init__(self):
        _check(self)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.channels)

    def select(self, names) -> Measurements:
        """The same data restricted to the channels `names` (refusing unknown names)."""
        names = list(names)
        missing = [n for n in names if n not in self.channels]
        if missing:
            raise MeasurementError(
                f"{self.source}: no channel {missing[0]!r}; the file has: "
                + ", ".join(self.channels)
            )
        return Measurements(
            self.t,
            {n: self.channels[n] for n in names},
            {n: s for n, s in self.noise.items() if n in names},
            self.source,
        )

    def with_noise(self, noise: Mapping[str, float] | float) -> Measurements:
        """Noise levels replaced: a number for every channel or `{channel: σ}`."""
        if not isinstance(noise, Mapping):
            noise = {n: float(noise) for n in self.channels}
        return Measurements(self.t, self.channels, {**self.noise, **noise}, self.source)

    def save(self, path: str) -> None:
        """Write as CSV or npz (chosen by the extension), atomically."""
        from ..io import atomic_write_bytes, atomic_write_npz

        ext = os.path.splitext(path)[1].lower()
        if ext == ".npz":
            extra = {f"sigma_{n}": np.asarray(s) for n, s in self.noise.items()}
            atomic_write_npz(path, t=self.t, **self.channels, **extra)
        elif ext == ".csv":
            lines = [f"# sigma_{n} = {s!r}" for n, s in self.noise.items()]
            lines.append(",".join(["t", *self.channels]))
            columns = np.column_stack([self.t, *self.channels.values()])
            body = io.StringIO()
            np.savetxt(body, columns, delimiter=",", fmt="%.17g")
            atomic_write_bytes(path, ("\n".join(lines) + "\n" + body.getvalue()).encode())
        else:
            raise MeasurementError(f"{path}: unknown format {ext!r}; use .csv or .npz")


def _check(m: Measurements) -> None:
    src = m.source
    t = np.asarray(m.t)
    if t.ndim != 1:
        raise MeasurementError(f"{src}: the time column must be 1-D, got shape {t.shape}")
    if t.size < 2:
        raise MeasurementError(f"{src}: need at least 2 samples, got {t.size}")
    _check_finite(src, "t", t)
    steps = np.diff(t)
    if np.any(steps <= 0):
        row = int(np.argmax(steps <= 0)) + 1
        raise MeasurementError(
            f"{src}: times must be strictly increasing; t[{row}] = {t[row]!r} s follows "
            f"t[{row - 1}] = {t[row - 1]!r} s"
        )
    if t[0] < 0:
        raise MeasurementError(f"{src}: times must be >= 0 s (the run starts at 0), got {t[0]!r}")
    if not m.channels:
        raise MeasurementError(f"{src}: no measured channel besides the time column")
    for name, values in m.channels.items():
        values = np.asarray(values)
        if values.shape != t.shape:
            raise MeasurementError(
                f"{src}: channel {name!r} has shape {values.shape}, the time column {t.shape}"
            )
        _check_finite(src, name, values)
    for name, sigma in m.noise.items():
        if name not in m.channels:
            raise MeasurementError(
                f"{src}: noise level given for {name!r}, which is not a measured channel "
                f"({', '.join(m.channels)})"
            )
        if not (math.isfinite(sigma) and sigma > 0):
            raise MeasurementError(
                f"{src}: noise level sigma_{name} = {sigma!r} is invalid: it must be finite "
                "and > 0 (one standard deviation, in the channel's unit)"
            )


# Largest magnitude of a measured value: a sum of squares of values beyond it overflows a
# float64 (sqrt(1.8e308) ≈ 1.3e154, with room for a sum over many samples).
MAX_MAGNITUDE = 1e150


def _check_finite(src, name, values):
    bad = ~np.isfinite(values)
    if np.any(bad):
        row = int(np.argmax(bad))
        raise MeasurementError(
            f"{src}: column {name!r} row {row} holds {values[row]!r}; every value must be "
            "a finite number"
        )
    huge = np.abs(values) > MAX_MAGNITUDE
    if np.any(huge):
        row = int(np.argmax(huge))
        raise MeasurementError(
            f"{src}: column {name!r} row {row} holds {float(values[row])!r}, beyond "
            f"±{MAX_MAGNITUDE:g}: its square overflows a float64 (a least-squares fit squares "
            "every residual); give the values in SI units"
        )


def _split_noise(src: str, items: Mapping[str, float], names) -> dict[str, float]:
    noise = {}
    for key, value in items.items():
        try:
            value = float(value)
        except (TypeError, ValueError):
            raise MeasurementError(
                f"{src}: noise level {key} = {value!r} is not a number"
            ) from None
        if key == "sigma":
            for n in names:
                noise.setdefault(n, value)
        else:
            noise[key.removeprefix("sigma_")] = value
    return noise


def _time_column(src: str, names) -> str:
    found = [n for n in TIME_NAMES if n in names]
    if not found:
        raise MeasurementError(
            f"{src}: no time column; name it 't' or 'time' (found: {', '.join(names) or 'none'})"
        )
    return found[0]


def _read_csv(path: str) -> Measurements:
    with open(path, encoding="utf-8") as fh:
        text = fh.read()
    lines = text.splitlines()
    noise_items: dict[str, str] = {}
    header_row = None
    for i, line in enumerate(lines):
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            body = stripped[1:].strip()
            if body.startswith("sigma") and "=" in body:
                key, value = (s.strip() for s in body.split("=", 1))
                noise_items[key] = value
            continue
        header_row = i
        break
    if header_row is None:
        raise MeasurementError(f"{path}: no header row (column names) found")
    names = [n.strip() for n in lines[header_row].split(",")]
    if any(not n for n in names):
        raise MeasurementError(f"{path}: empty column name in the header {lines[header_row]!r}")
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise MeasurementError(f"{path}: column {dup!r} appears twice in the header")
    rows = []
    for i, line in enumerate(lines[header_row + 1 :], start=header_row + 2):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        cells = line.split(",")
        if len(cells) != len(names):
            raise MeasurementError(
                f"{path}: line {i} has {len(cells)} values, the header has {len(names)} columns"
            )
        try:
            rows.append([float(c) for c in cells])
        except ValueError:
            bad = next(c for c in cells if not _is_float(c))
            raise MeasurementError(f"{path}: line {i}: {bad.strip()!r} is not a number") from None
    if not rows:
        raise MeasurementError(f"{path}: no data rows after the header")
    table = np.array(rows, dtype=float)
    time_name = _time_column(path, names)
    columns = {n: table[:, k] for k, n in enumerate(names)}
    t = columns.pop(time_name)
    noise = _split_noise(path, noise_items, list(columns))
    return Measurements(t, columns, noise, path)


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _read_npz(path: str) -> Measurements:
    try:
        archive = np.load(path, allow_pickle=False)
    except Exception as err:  # zipfile/pickle errors: say which file and why
        raise MeasurementError(f"{path}: not a readable npz file ({err})") from None
    with archive:
        arrays = {k: np.asarray(archive[k]) for k in archive.files}
    time_name = _time_column(path, list(arrays))
    t = arrays.pop(time_name).astype(float)
    noise_items = {k: arrays.pop(k) for k in list(arrays) if k.startswith("sigma")}
    channels = {}
    for k, v in arrays.items():
        if not np.issubdtype(v.dtype, np.number):
            raise MeasurementError(f"{path}: array {k!r} is not numeric (dtype {v.dtype})")
        channels[k] = v.astype(float)
    for k, v in noise_items.items():
        if np.size(v) != 1:
            raise MeasurementError(
                f"{path}: noise level {k!r} must be one number, got shape {v.shape}"
            )
    noise = _split_noise(path, {k: np.asarray(v).item() for k, v in noise_items.items()}, channels)
    return Measurements(t, channels, noise, path)


def load_measurements(path: str) -> Measurements:
    """Read a CSV or npz measurement file (format in the module docstring), checked."""
    if not os.path.isfile(path):
        raise MeasurementError(f"{path}: no such file")
    ext = os.path.splitext(path)[1].lower()
    if ext == ".csv":
        return _read_csv(path)
    if ext == ".npz":
        return _read_npz(path)
    raise MeasurementError(f"{path}: unknown format {ext!r}; give a .csv or .npz file")
