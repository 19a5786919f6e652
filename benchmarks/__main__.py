"""`python -m benchmarks` (from a source checkout; `make bench` runs `all`).

* `all [--quick] [--out DIR] [--allow-dirty]`: every measurement, each in a fresh process, then
  the page `DIR/performance.md` with `DIR/bench/work_precision.{json,png}` and
  `DIR/bench/targets.json` (DIR: `docs`, or `results/bench_quick` with `--quick`).
* `part NAME --json FILE [--quick]`: one measurement (work-precision, andrews, batch, ceiling,
  gradient, simulate, whole-process) into FILE; used by `all`.
* `tour [--allow-dirty]`: the README tour's commands timed, its `Time:` lines rewritten
  (`benchmarks/tour.py`); `all` runs it last when it writes to `docs`.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

# The code whose changes make the page stale (tests/test_page_freshness.py).
MEASURES = [
    "benchmarks",
    "examples/slider_crank_slider_x.csv",
    "jaxdeploy/_compilation_cache.py",
    "jaxdeploy/_described.py",
    "jaxdeploy/_design_program.py",
    "jaxdeploy/_program_cache.py",
    "jaxdeploy/_read_ahead.py",
    "jaxdeploy/analysis",
    "jaxdeploy/batch.py",
    "jaxdeploy/cli.py",
    "jaxdeploy/commands/fit.py",
    "jaxdeploy/commands/optimize.py",
    "jaxdeploy/commands/simulate.py",
    "jaxdeploy/commands/sweep.py",
    "jaxdeploy/contact",
    "jaxdeploy/fit",
    "jaxdeploy/mechanism",
    "jaxdeploy/objectives.py",
    "jaxdeploy/optimize.py",
    "jaxdeploy/scenes",
    "jaxdeploy/simulation.py",
    "jaxdeploy/solvers",
    "jaxdeploy/sweep.py",
    "tests/data/slider_crank_reference.npz",
]
PINNED = ("work-precision", "andrews", "batch", "ceiling", "gradient")  # one core, both sides
PARTS = ("work-precision", "andrews", "batch", "ceiling", "gradient", "simulate", "whole-process")
CUT = [
    "Work–precision over the first 4 ms of slider_crank only (the reference fixture's fine "
    "grid), not two revolutions, and not deploy_array (its implicit configurations take hours).",
    "Batch over 4 ms of slider_crank; one-at-a-time cost is the mean of 8 cases, not 256; no "
    "`group_size` variant, no two-core batch.",
    "Gradient over 0.2 s of deploy_array, not its 2 s.",
]


def _part(name: str, quick: bool) -> dict:
    from . import targets

    if name in PINNED and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    if name == "work-precision":
        from .work_precision import measure

        return measure(quick=quick, repeats=1 if quick else 3)
    if name == "andrews":
        from .andrews import measure as andrews

        return andrews(quick=quick, repeats=1 if quick else 3)
    if name == "batch":
        return targets.batch(
            cases=16 if quick else 256, singles=2 if quick else 8, shared_cases=4 if quick else 64
        )
    if name == "ceiling":
        return targets.solve_ceiling(cases=16 if quick else 256, iterations=200 if quick else 2000)
    if name == "gradient":
        return targets.gradient(t_end=0.02 if quick else 0.2, repeats=1 if quick else 2)
    if name == "simulate":
        return targets.simulate_cold_warm()
    if name == "whole-process":
        from .whole_process import measure as whole_process

        return whole_process()
    raise ValueError(f"part {name!r} is invalid; valid: {', '.join(PARTS)}")


def _bytecode() -> None:
    """The package's and the benchmarks' modules compiled to bytecode first, as an install
    leaves them (pip compiles a wheel's modules): every timed process then imports them as a
    user's does. A shell with PYTHONDONTWRITEBYTECODE set (this project's machines have it)
    would otherwise have every new process compile jaxdeploy's ~100 modules from source, 0.1
    to 0.2 s of each start-up measured."""
    import compileall

    for folder in ("jaxdeploy", "benchmarks"):
        compileall.compile_dir(folder, quiet=1)


def _all(args) -> int:
    from jaxdeploy.io import atomic_write_bytes, atomic_write_json

    from . import page, provenance
    from .work_precision import plot

    out = args.out or ("results/bench_quick" if args.quick else "docs")
    try:
        record = provenance.start(MEASURES, allow_dirty=args.allow_dirty)
    except RuntimeError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    os.makedirs(os.path.join(out, "bench"), exist_ok=True)
    _bytecode()
    results, began = {}, time.perf_counter()
    parts = [p for p in PARTS if not (args.quick and p == "simulate")]
    for name in parts:
        path = os.path.join(out, "bench", f".{name}.json")
        print(f"[{time.perf_counter() - began:6.0f} s] {name} ...", flush=True)
        command = [sys.executable, "-m", "benchmarks", "part", name, "--json", path]
        if subprocess.run(command + (["--quick"] if args.quick else [])).returncode != 0:
            print(f"error: part {name} failed (its output is above)", file=sys.stderr)
            return 1
        with open(path, encoding="utf-8") as f:
            results[name] = json.load(f)
        os.remove(path)
    record = provenance.finish(record)
    record["wall_s"] = time.perf_counter() - began
    wp = results.pop("work-precision")
    atomic_write_json(os.path.join(out, "bench", "work_precision.json"), wp)
    atomic_write_json(os.path.join(out, "bench", "targets.json"), results)
    plot(wp, os.path.join(out, "bench", "work_precision.png"))
    cut = CUT + (["--quick: a handful of configurations, short horizons, no simulate."]
                 if args.quick else [])  # fmt: skip
    command = "make bench" if not args.quick else "python -m benchmarks all --quick"
    text = page.render(record, wp, {**results, "simulate": results.get("simulate")},
                       command=command, cut=cut)  # fmt: skip
    atomic_write_bytes(os.path.join(out, "performance.md"), text.encode("utf-8"))
    print(f"wrote {out}/performance.md in {record['wall_s']:.0f} s "
          f"(load {record['load_start_1min']:.1f} → {record['load_end_1min']:.1f})")  # fmt: skip
    if args.quick or os.path.abspath(out) != os.path.abspath("docs"):
        return 0
    print("README tour ...", flush=True)
    from . import tour

    return tour.main("README.md", allow_dirty=args.allow_dirty)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    every = sub.add_parser("all", help="every measurement, then the page")
    every.add_argument("--quick", action="store_true", help="few configurations, short runs")
    every.add_argument("--out", default=None, help="folder of the page (default docs)")
    every.add_argument("--allow-dirty", action="store_true",
                       help="measure uncommitted code (the page is marked dirty)")  # fmt: skip
    walk = sub.add_parser("tour", help="time the README's tour, rewrite its Time: lines")
    walk.add_argument("--allow-dirty", action="store_true",
                      help="measure uncommitted code (the README is marked dirty)")  # fmt: skip
    one = sub.add_parser("part", help="one measurement into a JSON file")
    one.add_argument("name", choices=PARTS)
    one.add_argument("--json", required=True)
    one.add_argument("--quick", action="store_true")
    args = parser.parse_args(argv)
    if args.command == "all":
        return _all(args)
    if args.command == "tour":
        from . import tour

        return tour.main("README.md", allow_dirty=args.allow_dirty)
    from jaxdeploy.io import atomic_write_json

    atomic_write_json(args.json, _part(args.name, args.quick))
    return 0


if __name__ == "__main__":
    sys.exit(main())
