"""`benchmarks/tour.py`: the README tour's `Time:` lines and provenance are rewritten from a
run, every timed block has its line, and a mismatch is refused instead of mislabelled."""

import pathlib

import pytest

from benchmarks import tour

ROOT = pathlib.Path(__file__).resolve().parents[1]

README = """# x

## A five-minute tour

Times: not measured yet.

<!-- provenance {} -->

```bash
source .venv/bin/activate
```

```bash
jaxdeploy scenes
jaxdeploy scenes slider_crank
```

Time: old.

```bash
jaxdeploy simulate slider_crank
```

Time: old.

Writes `results/simulate/slider_crank-DATE-TIME/`: `summary.json`.

## Next

Time: untouched outside the tour.
"""

RECORD = {
    "commit": "0123456789abcdef",
    "dirty": False,
    "machine": {"cpu_model": "CPU", "cpu_count": 2},
    "load_start_1min": 0.5,
    "load_end_1min": 1.0,
    "measures": tour.MEASURES,
}


def _block(*commands):
    return {"commands": [{"command": c, "wall_s": 12.3, "cpu_s": 0.5, "phases": None}
                         for c in commands]}  # fmt: skip


def test_rewrite_replaces_each_time_line_and_the_provenance():
    blocks = [_block("jaxdeploy scenes", "jaxdeploy scenes slider_crank"), _block("x")]
    blocks[1]["commands"][0]["phases"] = {"build": 1.25, "compile": 20.0}
    out = tour.rewrite(README, blocks, RECORD)
    lines = [line for line in out.splitlines() if line.startswith("Time: ")]
    assert lines == [
        "Time: `jaxdeploy scenes` 12 s wall, 0.5 s CPU; `jaxdeploy scenes slider_crank` 12 s "
        "wall, 0.5 s CPU.",
        "Time: 12 s wall, 0.5 s CPU (phases: build 1.2 s, compile 20 s).",
        "Time: untouched outside the tour.",
    ]
    assert "Writes `results/simulate/slider_crank-DATE-TIME/`" in out
    assert tour.provenance.read(out)["commit"] == RECORD["commit"]
    assert "at commit `0123456789ab`" in out and "not measured yet" not in out


def test_rewrite_refuses_a_block_without_its_time_line():
    broken = README.replace(
        "Time: old.\n\n```bash\njaxdeploy simulate", "```bash\njaxdeploy simulate"
    )
    with pytest.raises(RuntimeError, match="Time:"):
        tour.rewrite(broken, [_block("a", "b"), _block("c")], RECORD)
    with pytest.raises(RuntimeError, match="timed blocks measured"):
        tour.rewrite(README, [_block("a", "b")], RECORD)


def test_the_readme_tour_has_a_time_line_per_timed_block():
    """The real README: as many `Time:` lines as blocks the tour would time, so `make bench`
    can rewrite them (checked with a dry rewrite, nothing run)."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    sections = dict(tour.sections(text))
    timed = [
        b
        for language, b, _ in sections[tour.TOUR]
        if language == "bash" and any(map(tour.timed, b))
    ]
    blocks = [_block(*filter(tour.timed, b)) for b in timed]
    out = tour.rewrite(text, blocks, RECORD)
    assert out.count("\nTime: 12 s wall") + out.count("\nTime: `") == len(timed)
