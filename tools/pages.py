"""Regenerate every generated docs page, in order, on committed code: `make pages`
(`python -m tools.pages`).

Each generator records in the block it writes (`jaxdeploy.pages`) the commit it ran at and
the paths it measures; `tests/test_page_freshness.py` fails once a later commit changes one of
those paths. `GENERATORS` below is the one list of what writes which page, in the order they
must run, with the cost measured on this project's 2-core machine (CPU minutes, user +
system, of the generator's process and its children; the load beside it in the docs table,
docs/pages.md).

    python -m tools.pages                 # every generator (hours: see `--list`)
    python -m tools.pages --quick         # only those under QUICK_MINUTES of CPU each
    python -m tools.pages --only restitution_table extremes_sampling
    python -m tools.pages --list          # what would run, and the cost of each

A generator refuses a dirty tree (changes outside docs/ and README.md): commit first. The run
stops at the first generator that fails; the pages already written stay written.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import resource
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
QUICK_MINUTES = 10.0


@dataclasses.dataclass(frozen=True)
class Generator:
    name: str
    argv: tuple[str, ...]  # run with the checkout on PYTHONPATH
    pages: tuple[str, ...]  # what it writes (pages; blocks in brackets)
    cpu_min: float  # measured cost, CPU minutes (see docs/pages.md for the load)
    cwd: str = "."  # relative to the checkout
    note: str = ""


PY = sys.executable

# In order: the geometry script writes the scene's data (every deploy_array page measures
# it), verify_mechanics.py rewrites verification.md whole before report.py fills its block,
# identification.py makes the measurements identification_landscape.py reads.
GENERATORS = (
    Generator(
        "deploy_array_geometry",
        (PY, "experiments/deploy_array_geometry.py"),
        ("docs/deploy_array_geometry.md [geometry]",),
        0.3,
    ),
    Generator(
        "bench",
        (PY, "-m", "benchmarks", "all"),
        ("docs/performance.md", "docs/bench/", "README.md [tour times]"),
        13.0,
        note="make bench; installs the bench extra (exudyn)",
    ),
    Generator(
        "verify_mechanics", (PY, "tests/verify_mechanics.py"), ("docs/verification.md",), 5.0
    ),
    Generator(
        "independent_report",
        (PY, "-m", "independent.report"),
        ("docs/verification.md [independent-references]",),
        2.0,
        cwd="tests",
    ),
    Generator(
        "solver_crossover",
        (PY, "-m", "independent.solver_crossover"),
        ("docs/solver_by_tolerance.md [solver-by-tolerance]",),
        4.0,
        cwd="tests",
    ),
    Generator(
        "deploy_array_report",
        (PY, "-m", "independent.deploy_array_report"),
        ("docs/deploy_array.md [independent-check]",),
        4.0,
        cwd="tests",
    ),
    Generator(
        "contact_laws",
        (PY, "experiments/contact_laws.py"),
        ("docs/contact.md [contact-laws-figures]",),
        0.5,
    ),
    Generator(
        "clearance_sides",
        (PY, "experiments/clearance_sides.py"),
        ("docs/contact.md [clearance_sides]",),
        0.5,
    ),
    Generator(
        "restitution_table", (PY, "experiments/restitution_table.py"), ("docs/restitution.md",), 3.5
    ),
    Generator(
        "extremes_sampling",
        (PY, "experiments/extremes_sampling.py"),
        ("docs/output_extremes.md",),
        3.2,
    ),
    Generator(
        "generalized_alpha_error_control",
        (PY, "experiments/generalized_alpha_error_control.py"),
        ("docs/generalized_alpha_error.md [generalized-alpha-error]",),
        3.0,
    ),
    Generator(
        "spectral_peak",
        (PY, "experiments/spectral_peak.py", "--rerun"),
        ("docs/spectral_peak.md",),
        5.5,
    ),
    Generator(
        "deploy_array_latch",
        (PY, "experiments/deploy_array_latch.py"),
        ("docs/deploy_array.md [latch-comparison]",),
        3.0,
    ),
    Generator(
        "deploy_array_impact_rule",
        (PY, "experiments/deploy_array_impact_rule.py"),
        ("docs/deploy_array.md [impact-velocity-rule]",),
        3.0,
    ),
    Generator(
        "robustness",
        (PY, "experiments/robustness.py", "all"),
        ("docs/robustness.md",),
        35.0,
        note="reuses results/robustness/*.json: delete them first for a fresh run",
    ),
    Generator(
        "identification",
        (PY, "experiments/identification.py", "--regenerate", "--rerun"),
        ("docs/identification.md [identification]",),
        32.0,
    ),
    Generator(
        "identification_landscape",
        (PY, "experiments/identification_landscape.py"),
        ("docs/identification.md [identification_landscape]",),
        4.0,
    ),
    Generator(
        "identification_independent",
        (PY, "experiments/identification_independent.py", "--rerun"),
        ("docs/identification.md [identification_independent]",),
        30.0,
    ),
    Generator(
        "identification_solvers",
        (PY, "experiments/identification_solvers.py", "--rerun"),
        ("docs/identification.md [identification_solvers]",),
        30.0,
    ),
    Generator(
        "gradient_sensitivity",
        (PY, "experiments/gradient_sensitivity.py"),
        ("docs/identification.md [gradient_sensitivity]",),
        6.0,
    ),
    Generator(
        "gradient_horizon",
        (PY, "experiments/gradient_horizon.py"),
        ("docs/identification.md [gradient_horizon]",),
        7.0,
    ),
    Generator(
        "design_study",
        (PY, "experiments/design_study.py", "all"),
        ("docs/design.md",),
        25.0,
        note="reuses results/design_study/: delete it first for a fresh run",
    ),
    Generator(
        "paper_study",
        (PY, "experiments/paper_study.py", "--rerun"),
        ("docs/paper_study.md",),
        100.0,
    ),
)


def run(generator: Generator) -> float:
    """Run one generator; its CPU minutes (children's user + system)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [ROOT, os.environ.get(
        "PYTHONPATH")]))}  # fmt: skip
    start = time.perf_counter()
    subprocess.run(generator.argv, cwd=os.path.join(ROOT, generator.cwd), env=env, check=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime) / 60
    print(f"[pages] {generator.name}: {cpu:.1f} CPU-min, "
          f"{(time.perf_counter() - start) / 60:.1f} min wall, load "
          f"{os.getloadavg()[0]:.1f}", flush=True)  # fmt: skip
    return cpu


def select(only=(), quick=False):
    names = {g.name for g in GENERATORS}
    unknown = sorted(set(only) - names)
    if unknown:
        raise SystemExit(f"unknown generator(s) {unknown}; choose from {sorted(names)}")
    chosen = [g for g in GENERATORS if not only or g.name in only]
    return [g for g in chosen if not quick or g.cpu_min <= QUICK_MINUTES]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", default=(), metavar="NAME", help="these generators")
    ap.add_argument("--quick", action="store_true",
                    help=f"only generators under {QUICK_MINUTES:g} CPU-min each")  # fmt: skip
    ap.add_argument("--list", action="store_true", help="list and stop")
    args = ap.parse_args(argv)
    chosen = select(args.only, args.quick)
    total = sum(g.cpu_min for g in chosen)
    print(f"[pages] {len(chosen)} generators, about {total:.0f} CPU-min measured", flush=True)
    for g in chosen:
        print(f"  {g.name:32s} {g.cpu_min:6.1f} CPU-min  {', '.join(g.pages)}"
              + (f"  ({g.note})" if g.note else ""))  # fmt: skip
    if args.list:
        return 0
    for g in chosen:
        run(g)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
