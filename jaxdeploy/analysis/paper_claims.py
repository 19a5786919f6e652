"""The claims of the seed paper's section 4 (W24) as checks on deploy_array runs: the metrics
behind each claim, their numerical uncertainty, and a verdict per claim.

W24 states its roughness/clearance findings in words; each claim here is turned into a
comparison of metrics between the cases it names (e.g. "decays faster with roughness": the
settling time falls from Ra 0.8 to 1.6 to 3.2 µm). A comparison counts only when the difference
exceeds the sum of the two values' uncertainties ("≈" otherwise). Used by
experiments/paper_study.py (docs/paper_study.md).

Cases are indexed 0–4: Ra 0.8, 1.6, 3.2 µm at c 0.05 mm, then c 0.01 and 0.1 mm at Ra 1.6 µm
(`ROUGHNESS_STUDY`, `CLEARANCE_STUDY`).
"""

from __future__ import annotations

import numpy as np

from .deploy_array import PANELS, SPECTRUM_SEGMENT
from .spectra import peak_frequency, welch_psd

ROUGHNESS_STUDY = [0, 1, 2]  # Ra 0.8, 1.6, 3.2 µm at c 0.05 mm
CLEARANCE_STUDY = [3, 1, 4]  # c 0.01, 0.05, 0.1 mm at Ra 1.6 µm
ENVELOPE_WINDOW_S = 0.02  # moving-RMS window for envelopes (two periods of 100 Hz)
FLUTTER_WINDOW_S = 0.1  # "at the locking moment": the first 0.1 s after lock
LATE_WINDOW_S = 0.2  # "after stabilisation": the run's last 0.2 s


def moving_rms(t, x, width=ENVELOPE_WINDOW_S):
    """RMS of x over a centred window of `width` seconds (uniform sampling)."""
    n = max(1, int(round(width / float(t[1] - t[0]))))
    return np.sqrt(np.convolve(x**2, np.ones(n) / n, mode="same"))


def _late(t):
    return t >= t[-1] - LATE_WINDOW_S


def post_lock_oscillation(t, x, t_lock):
    """Post-lock part of `x` with its resting offset (mean over the late window) removed: a
    journal that settles off-centre leaves a constant deviation that is not vibration."""
    post = t > t_lock
    return t[post], x[post] - x[_late(t)].mean()


def settling_time(t, x, t_lock, fraction=0.1):
    """Time from lock until the moving-RMS envelope of the post-lock oscillation stays below
    `fraction` of its maximum (nan if it never does within the run)."""
    tp, xp = post_lock_oscillation(t, x, t_lock)
    env = moving_rms(tp, xp)
    above = np.flatnonzero(env > fraction * env.max())
    if len(above) == 0 or above[-1] >= len(tp) - 1 - int(ENVELOPE_WINDOW_S / (tp[1] - tp[0])):
        return float("nan")
    return float(tp[above[-1]] - t_lock)


def spectral_peak(t, x, segment=SPECTRUM_SEGMENT, f_min=5.0):
    """`(f, level)`: the Welch peak frequency [Hz] (`spectra.peak_frequency`) and the level
    sqrt(P_max Δf) at the largest bin, the RMS of x within that bin [x's unit]."""
    f, psd = welch_psd(t, x, segment)
    keep = f >= f_min
    level = float(np.sqrt(np.max(np.asarray(psd)[keep]) * (f[1] - f[0])))
    return peak_frequency(t, x, segment=segment, f_min=f_min), level


def case_metrics(o) -> dict:
    """The numbers behind the claims for one case, from `deploy_array_outputs` `o`."""
    t, t_lock = o["t"], o["lock_time"]
    deploy, locked = t <= t_lock, t > t_lock
    flutter = locked & (t <= t_lock + FLUTTER_WINDOW_S)
    late = _late(t)
    dev = o["alpha"] - o["alpha_ideal"]
    m = {
        "lock_time": t_lock,
        "angle_dev_deploy": np.abs(dev[deploy]).max(),
        "angle_dev_locked": np.abs(dev[locked]).max(),
        "angle_settling": settling_time(t, dev, t_lock),
    }
    for panel in PANELS:
        for where in ("centre", "tip"):
            d = o[f"{panel}_{where}_deviation"]
            for k, axis in enumerate("xy"):
                key = f"{panel}_{where}_{axis}"
                m[f"{key}_deploy"] = np.abs(d[deploy, k]).max()
                m[f"{key}_flutter"] = np.abs(d[flutter, k]).max()
                m[f"{key}_late_rms"] = float(np.std(d[late, k]))
                m[f"{key}_settling"] = settling_time(t, d[:, k], t_lock)
        # Spectra of the interval-mean Y acceleration (docs/spectral_peak.md).
        acc = o[f"{panel}_mean_acceleration"][:, 1]
        after = t[:-1] >= t_lock
        m[f"{panel}_freq_locked"], m[f"{panel}_amp_locked"] = spectral_peak(
            t[:-1][after], acc[after]
        )
        m[f"{panel}_acc_settling"] = settling_time(t[:-1], acc, t_lock)
    forces = [np.asarray(h["normal_force"]) for h in o["joints"].values()]
    m["max_contact_force"] = max(float(f.max()) for f in forces)
    return {k: float(v) for k, v in m.items()}


class Evidence:
    """Metric values per case and their numerical uncertainty.

    `values[i]`, `uncertainties[i]`: `{metric: value}` of case i (None for a case not run).
    """

    def __init__(self, values, uncertainties):
        self.values, self.uncertainties = values, uncertainties

    def value(self, metric, i):
        return self.values[i][metric]

    def uncertainty(self, metric, i):
        u = self.uncertainties[i][metric]
        return u if np.isfinite(u) else np.inf

    def compare(self, metric_a, i, metric_b, j):
        """'<', '>' or '≈' (difference within the summed uncertainty); '?' if undefined."""
        a, b = self.value(metric_a, i), self.value(metric_b, j)
        if not (np.isfinite(a) and np.isfinite(b)):
            return "?"
        u = self.uncertainty(metric_a, i) + self.uncertainty(metric_b, j)
        if a - b > u:
            return ">"
        if b - a > u:
            return "<"
        return "≈"

    def trend(self, metric, cases):
        """Comparisons between consecutive cases, e.g. ('<', '>') = rises then falls."""
        return tuple(
            self.compare(metric, a, metric, b) for a, b in zip(cases, cases[1:], strict=False)
        )

    def fmt(self, metric, cases, scale=1.0, unit="", digits=3):
        def one(i):
            value = self.value(metric, i)
            if not np.isfinite(value):
                return "not within the run"
            return f"{value * scale:.{digits}g}±{self.uncertainty(metric, i) * scale:.1g}"

        return ", ".join(one(i) for i in cases) + (f" {unit}" if unit else "")


def verdict_from(checks):
    """Combine per-series verdicts: all agree → agrees; any resolved disagreement and no
    agreement → disagrees; mixed → partly; nothing resolved → not resolved."""
    if all(c == "agrees" for c in checks):
        return "agrees"
    if all(c == "not resolved" for c in checks):
        return "not resolved"
    if "agrees" in checks:
        return "partly"
    return "disagrees"


def trend_verdict(trend, expected):
    if trend == expected:
        return "agrees"
    if "≈" in trend or "?" in trend:
        resolved = [(t, e) for t, e in zip(trend, expected, strict=True) if t not in "≈?"]
        if all(t == e for t, e in resolved) and resolved:
            return "not resolved"
        if not resolved:
            return "not resolved"
    return "disagrees"


def comparison_verdict(comparison, expected):
    """'agrees' if the resolved comparison is the expected one, 'not resolved' if within the
    error bars ('≈') or undefined ('?'), else 'disagrees'."""
    if comparison == expected:
        return "agrees"
    return "not resolved" if comparison in ("≈", "?") else "disagrees"


def spread_verdict(ev, metric, cases, limit):
    """'Similar across cases': max/min ratio of the values below `limit`; 'not resolved' when
    a value does not exceed its uncertainty (the ratio would compare numerical noise, e.g.
    vibration that has decayed to round-off)."""
    vals = np.array([ev.value(metric, i) for i in cases])
    ratio = vals.max() / vals.min()
    if any(abs(v) <= ev.uncertainty(metric, i) for v, i in zip(vals, cases, strict=True)):
        return ratio, "not resolved"
    return ratio, ("agrees" if ratio < limit else "disagrees")


MU_RAD = 1e6  # rad → µrad
UM_PER_M = 1e6


def per_panel_axis(ev: Evidence, suffix, cases, judge):
    """`(checks, texts)` of a claim about both panels' centre deviations along X and Y: for
    each metric `{panel}_centre_{axis}_{suffix}`, `judge(metric)` gives `(verdict, note)`, and
    the text lists the values over `cases` [µm] with the note."""
    checks, texts = [], []
    for panel in PANELS:
        for axis in "xy":
            m = f"{panel}_centre_{axis}_{suffix}"
            verdict, note = judge(m)
            checks.append(verdict)
            texts.append(f"{panel} {axis.upper()}: {ev.fmt(m, cases, UM_PER_M)} µm ({note})")
    return checks, texts


def trend_judge(ev: Evidence, cases, expected):
    """A `per_panel_axis` judge: the metric's trend over `cases` against `expected`."""

    def judge(metric):
        t = ev.trend(metric, cases)
        return trend_verdict(t, expected), "".join(t)

    return judge


def claims(ev: Evidence, clearance=True):
    """The claims of W24 §4 as rows `{id, figure, claim, ours, verdict}`; `clearance=False`:
    the roughness claims (R*) only (for runs of the roughness cases alone)."""
    R, C = ROUGHNESS_STUDY, CLEARANCE_STUDY
    rows = []

    def add(cid, fig, text, ours, verdict):
        rows.append({"id": cid, "figure": fig, "claim": text, "ours": ours, "verdict": verdict})

    t = ev.trend("angle_dev_deploy", R)
    add(
        "R1",
        "9a",
        "Deployment-phase angle deviation first increases, then decreases with roughness.",
        f"max |α−α_ideal| = {ev.fmt('angle_dev_deploy', R, MU_RAD, 'µrad')}; trend {''.join(t)}",
        trend_verdict(t, ("<", ">")),
    )
    ratio, v = spread_verdict(ev, "angle_dev_locked", R, 1.5)
    add(
        "R2",
        "9a",
        "Locked-stage angle deviation range: no significant difference between roughnesses.",
        f"max |α−α_ideal| after lock = {ev.fmt('angle_dev_locked', R, MU_RAD, 'µrad')}; "
        f"max/min {ratio:.2f} (similar: < 1.5)",
        v,
    )
    t = ev.trend("angle_settling", R)
    add(
        "R3",
        "9b",
        "After locking, the angle deviation decays faster with increasing roughness.",
        f"10 % settling time = {ev.fmt('angle_settling', R, 1e3, 'ms')}; trend {''.join(t)}",
        trend_verdict(t, (">", ">")),
    )
    checks, texts = per_panel_axis(ev, "deploy", R, trend_judge(ev, R, (">", ">")))
    add(
        "R4",
        "10–13",
        "Deployment stage: the smaller the roughness, the larger the panels' displacement "
        "deviation.",
        "; ".join(texts),
        verdict_from(checks),
    )
    checks, texts = per_panel_axis(ev, "flutter", R, trend_judge(ev, R, (">", ">")))
    add(
        "R5",
        "10–13",
        "At the locking moment, the smaller the roughness, the larger the flutter amplitude.",
        "max |deviation| in the first 0.1 s after lock: " + "; ".join(texts),
        verdict_from(checks),
    )

    def similar(metric):
        ratio, verdict = spread_verdict(ev, metric, R, 2.0)
        return verdict, f"×{ratio:.1f}"

    checks, texts = per_panel_axis(ev, "late_rms", R, similar)
    add(
        "R6",
        "10–13",
        "Once stable, the flutter amplitudes of the different roughnesses are basically similar.",
        "RMS of the deviation over the last 0.2 s: " + "; ".join(texts) + " (similar: max/min < 2)",
        verdict_from(checks),
    )
    ratios = [
        ev.value("panel2_centre_x_deploy", i) / ev.value("panel1_centre_x_deploy", i) for i in R
    ]
    tip_ratios = [
        ev.value("panel2_tip_x_deploy", i) / ev.value("panel1_tip_x_deploy", i) for i in R
    ]
    add(
        "R7",
        "10a, 12a",
        "Deployment stage: panel 2's X displacement deviation is about twice panel 1's.",
        "panel 2 / panel 1 max |ΔX|, centres: "
        + ", ".join(f"{r:.2f}" for r in ratios)
        + "; tips: "
        + ", ".join(f"{r:.2f}" for r in tip_ratios)
        + " (about twice: 1.5–2.5)",
        verdict_from(["agrees" if 1.5 <= r <= 2.5 else "disagrees" for r in ratios]),
    )
    checks = [
        comparison_verdict(c, "<")
        for c in (ev.compare("panel2_centre_y_deploy", i, "panel1_centre_y_deploy", i) for i in R)
    ]
    add(
        "R8",
        "11a, 13a",
        "Deployment stage: panel 2's Y deviation is smaller than panel 1's.",
        f"max |ΔY| panel 1: {ev.fmt('panel1_centre_y_deploy', R, UM_PER_M)} µm; "
        f"panel 2: {ev.fmt('panel2_centre_y_deploy', R, UM_PER_M)} µm",
        verdict_from(checks),
    )
    checks = []
    for i in R:
        for c in (
            ev.compare("panel2_tip_x_settling", i, "panel1_tip_x_settling", i),
            ev.compare("panel2_tip_x_late_rms", i, "panel1_tip_x_late_rms", i),
        ):
            checks.append(comparison_verdict(c, "<"))
    add(
        "R9",
        "10b, 12b",
        "After locking, the X deviation of panel 2's end decays faster, and once stable is "
        "lower than panel 1's.",
        f"X settling of the tips, panel 1: {ev.fmt('panel1_tip_x_settling', R, 1e3)} ms, "
        f"panel 2: {ev.fmt('panel2_tip_x_settling', R, 1e3)} ms; late RMS panel 1: "
        f"{ev.fmt('panel1_tip_x_late_rms', R, UM_PER_M)} µm, panel 2: "
        f"{ev.fmt('panel2_tip_x_late_rms', R, UM_PER_M)} µm",
        verdict_from(checks),
    )
    checks = [
        comparison_verdict(c, ">")
        for c in (ev.compare("panel2_tip_y_late_rms", i, "panel1_tip_y_late_rms", i) for i in R)
    ]
    add(
        "R10",
        "11b, 13b",
        "Once stable, panel 2's Y deviation is larger than panel 1's.",
        f"late RMS of ΔY at the tips, panel 1: {ev.fmt('panel1_tip_y_late_rms', R, UM_PER_M)} µm;"
        f" panel 2: {ev.fmt('panel2_tip_y_late_rms', R, UM_PER_M)} µm",
        verdict_from(checks),
    )
    t = ev.trend("panel1_amp_locked", R)
    add(
        "R11",
        "14",
        "Panel 1's vibration amplitude first increases, then decreases with roughness "
        "(largest at Ra 1.6).",
        f"post-lock spectral peak of panel 1's Y acceleration: "
        f"{ev.fmt('panel1_amp_locked', R, 1, 'm/s²')}; trend {''.join(t)}",
        trend_verdict(t, ("<", ">")),
    )
    c1 = ev.compare("panel1_freq_locked", R[1], "panel1_freq_locked", R[0])
    c2 = ev.compare("panel1_freq_locked", R[1], "panel1_freq_locked", R[2])
    c3 = ev.compare("panel1_freq_locked", R[0], "panel1_freq_locked", R[2])
    checks = [comparison_verdict(c, want) for c, want in ((c1, ">"), (c2, ">"), (c3, "<"))]
    add(
        "R12",
        "14",
        "Panel 1's peak frequency is highest at Ra 1.6 and lowest at Ra 0.8.",
        f"panel 1 post-lock peak frequency: {ev.fmt('panel1_freq_locked', R, 1, 'Hz')}",
        verdict_from(checks),
    )
    freqs = [ev.value("panel2_freq_locked", i) for i in R]
    add(
        "R13",
        "15",
        "Panel 2 vibrates mainly between 90 and 100 Hz.",
        f"panel 2 post-lock peak frequency: {ev.fmt('panel2_freq_locked', R, 1, 'Hz')}",
        verdict_from(["agrees" if 90 <= f <= 100 else "disagrees" for f in freqs]),
    )
    lowest = [ev.compare("panel2_amp_locked", R[2], "panel2_amp_locked", i) for i in R[:2]]
    fastest = [ev.compare("panel2_acc_settling", R[2], "panel2_acc_settling", i) for i in R[:2]]
    checks = [comparison_verdict(c, "<") for c in lowest + fastest]
    add(
        "R14",
        "15",
        "Panel 2: Ra 3.2 gives the lowest vibration peak and the fastest attenuation.",
        f"panel 2 peak: {ev.fmt('panel2_amp_locked', R, 1, 'm/s²')}; 10 % settling of its "
        f"acceleration: {ev.fmt('panel2_acc_settling', R, 1e3, 'ms')}",
        verdict_from(checks),
    )
    if not clearance:
        return rows
    t = ev.trend("angle_dev_deploy", C)
    add(
        "C1",
        "16a",
        "Deployment-phase angle deviation range decreases as the clearance increases.",
        f"max |α−α_ideal| (c = 0.01, 0.05, 0.1 mm): "
        f"{ev.fmt('angle_dev_deploy', C, MU_RAD, 'µrad')}; trend {''.join(t)}",
        trend_verdict(t, (">", ">")),
    )
    t = ev.trend("angle_settling", C)
    add(
        "C2",
        "16b",
        "After locking, the angle deviation attenuates faster with larger clearance.",
        f"10 % settling time: {ev.fmt('angle_settling', C, 1e3, 'ms')}; trend {''.join(t)}",
        trend_verdict(t, (">", ">")),
    )
    checks, texts = per_panel_axis(ev, "deploy", C, trend_judge(ev, C, ("<", "<")))
    add(
        "C3",
        "17–20",
        "Deployment stage: X and Y displacement deviation ranges of both panels increase with "
        "clearance.",
        "; ".join(texts),
        verdict_from(checks),
    )
    checks, texts = [], []
    for panel in PANELS:
        growth = {
            axis: ev.value(f"{panel}_centre_{axis}_deploy", C[2])
            / ev.value(f"{panel}_centre_{axis}_deploy", C[0])
            for axis in "xy"
        }
        checks.append("agrees" if growth["y"] < growth["x"] else "disagrees")
        texts.append(f"{panel}: X ×{growth['x']:.2f}, Y ×{growth['y']:.2f}")
    add(
        "C4",
        "17–20",
        "The clearance influences the Y displacement deviation least.",
        "growth of max deviation from c = 0.01 to 0.1 mm, " + "; ".join(texts),
        verdict_from(checks),
    )
    t = ev.trend("panel1_amp_locked", C)
    add(
        "C5",
        "21",
        "Panel 1's spectral peak decreases as the clearance increases.",
        f"panel 1 post-lock peak: {ev.fmt('panel1_amp_locked', C, 1, 'm/s²')}; trend {''.join(t)}",
        trend_verdict(t, (">", ">")),
    )
    ta, tf = ev.trend("panel2_amp_locked", C), ev.trend("panel2_freq_locked", C)
    add(
        "C6",
        "22",
        "Panel 2's peak amplitude and peak frequency first increase, then decrease with clearance.",
        f"panel 2 peak: {ev.fmt('panel2_amp_locked', C, 1, 'm/s²')} ({''.join(ta)}); "
        f"frequency {ev.fmt('panel2_freq_locked', C, 1, 'Hz')} ({''.join(tf)})",
        verdict_from([trend_verdict(ta, ("<", ">")), trend_verdict(tf, ("<", ">"))]),
    )
    checks = []
    for i in C:
        for c, want in (
            (ev.compare("panel2_amp_locked", i, "panel1_amp_locked", i), ">"),
            (ev.compare("panel2_freq_locked", i, "panel1_freq_locked", i), "<"),
        ):
            checks.append(comparison_verdict(c, want))
    add(
        "C7",
        "21 vs 22",
        "Panel 2 vibrates with a larger amplitude but a lower peak frequency than panel 1.",
        f"peaks panel 1: {ev.fmt('panel1_amp_locked', C, 1, 'm/s²')}, panel 2: "
        f"{ev.fmt('panel2_amp_locked', C, 1, 'm/s²')}; frequencies panel 1: "
        f"{ev.fmt('panel1_freq_locked', C, 1, 'Hz')}, panel 2: "
        f"{ev.fmt('panel2_freq_locked', C, 1, 'Hz')}",
        verdict_from(checks),
    )
    return rows


# --------------------------------------------------------------------------------------------
