"""Regenerate every generated docs page, in order, on committed code: `make pages`
(`python -m tools.pages`).

Each generator records in the block it writes (`jaxdeploy.pages`) the commit it ran at and
the paths it measures; `tests/test_page_freshness.py` fails once a later commit changes one of
those paths. `GENERATORS` below is the one list of what writes which page, in the order they
must run, with the cost measured on this project's 2-core machine.

    python -m tools.pages                 # every generator (hours: see `--list`)
    python -m tools.pages --stale         # only those whose pages are stale
    python -m tools.pages --quick         # only those under QUICK_MINUTES each
    python -m tools.pages --only restitution_table extremes_sampling
    python -m tools.pages --list          # what would run, its cost, and why it is stale
    python -m tools.pages --jobs 2        # two at a time where they share no page

With `--jobs N` up to N generators run at once (`schedule`): one whose pages another writes
waits for it (the list's order is kept among them: verify_mechanics writes verification.md
whole before independent_report writes its block, identification.py measures what
identification_landscape.py reads), and one that times the machine (`alone`: `make bench`)
runs with nothing beside it, the generators after it waiting. Most generators keep about one
core busy (their CPU and wall minutes below), so on two cores two at a time take about half
the wall time; each one's output then goes to a log file, and its CPU time is its own
(`os.wait4`).

A generator refuses a dirty tree (changes outside docs/ and README.md): commit first. A
generator that exits non-zero (a fit that misses its criterion writes its page and says so)
does not stop the others; the run's exit status is 1 then. The long studies' stored runs
(`results/robustness`, `results/design_study`) are moved aside first so that every number is
made at this commit (`--keep-results` reuses them; the page records their commits).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import resource
import subprocess
import sys
import time

from jaxdeploy import pages

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
QUICK_MINUTES = 12.0  # make bench (11.9 min) is in the quick set: its pages go stale most often


@dataclasses.dataclass(frozen=True)
class Generator:
    name: str
    argv: tuple[str, ...]  # run with the checkout on PYTHONPATH
    pages: tuple[str, ...]  # what it writes: a page (whole), or "page [block]"
    minutes: float  # its cost, minutes on this project's 2-core machine (`measured` says how;
    # the larger of CPU and wall minutes where both are known)
    measured: str  # CPU or wall, the load, and the run it comes from
    cwd: str = "."  # relative to the checkout
    results: str = ""  # a folder of stored runs it reuses: moved aside first (--keep-results)
    alone: bool = False  # it times the machine: nothing runs beside it (--jobs)


PY = sys.executable
I = "docs/identification.md"

# In order: verify_mechanics.py rewrites verification.md whole (keeping the blocks of other
# scripts) before report.py writes its block; identification.py makes the measurements
# identification_landscape.py reads. The measured costs: CPU minutes (user + system) where
# said, else wall minutes; "today": measured on 2026-11-27 on a copy of main at load 14-22
# (other helpers' jobs), CPU time being the less load-sensitive number.
GENERATORS = (
    Generator("deploy_array_geometry", (PY, "experiments/deploy_array_geometry.py"),
              ("docs/deploy_array_geometry.md [geometry]",), 0.1, "CPU, today"),
    Generator("bench", (PY, "-m", "benchmarks", "all"),
              ("docs/performance.md", "README.md"), 11.9,
              "11.9 CPU-min, 10.7 min wall, load 1.4, at 86c338a, alone (tour included); make "
              "bench's pages: docs/bench/, the README's tour times", alone=True),
    Generator("verify_mechanics", (PY, "tests/verify_mechanics.py"), ("docs/verification.md",),
              0.6,
              "0.6 CPU-min, 0.6 min wall, load 2.0, at 15ad936, beside another generator"),
    Generator("independent_report", (PY, "-m", "independent.report"),
              ("docs/verification.md [independent-references]",), 2,
              "1.4 CPU-min, 2 min wall, load 3.4, at 15ad936, beside another generator",
              cwd="tests"),
    Generator("solver_crossover", (PY, "-m", "independent.solver_crossover"),
              ("docs/solver_by_tolerance.md [solver-by-tolerance]",), 1.1,
              "0.9 CPU-min, 1.1 min wall, load 3.7, at 15ad936, beside another generator",
              cwd="tests"),
    Generator("deploy_array_report", (PY, "-m", "independent.deploy_array_report"),
              ("docs/deploy_array.md [independent-check]",), 2.4,
              "1.5 CPU-min, 2.4 min wall, load 3.7, at 15ad936, beside another generator",
              cwd="tests"),
    Generator("contact_laws", (PY, "experiments/contact_laws.py"),
              ("docs/contact.md [contact-laws-figures]",), 0.25, "CPU, today (14.5 s)"),
    Generator("clearance_sides", (PY, "experiments/clearance_sides.py"),
              ("docs/contact.md [clearance_sides]",), 0.27, "CPU, today (16 s)"),
    Generator("restitution_table", (PY, "experiments/restitution_table.py"),
              ("docs/restitution.md",), 0.6,
              "0.5 CPU-min, 0.6 min wall, load 3.9, at 15ad936, beside another generator"),
    Generator("extremes_sampling", (PY, "experiments/extremes_sampling.py"),
              ("docs/output_extremes.md",), 2.1,
              "1.7 CPU-min, 2.1 min wall, load 3.8, at 15ad936, beside another generator"),
    Generator("generalized_alpha_error_control",
              (PY, "experiments/generalized_alpha_error_control.py"),
              ("docs/generalized_alpha_error.md [generalized-alpha-error]",), 1.4,
              "1.3 CPU-min, 1.4 min wall, load 3.5, at 15ad936, beside another generator"),
    Generator("spectral_peak", (PY, "experiments/spectral_peak.py", "--rerun"),
              ("docs/spectral_peak.md",), 3,
              "3 CPU-min, 3 min wall, load 2.8, at 15ad936, beside another generator"),
    Generator("deploy_array_latch", (PY, "experiments/deploy_array_latch.py"),
              ("docs/deploy_array.md [latch-comparison]",), 0.9,
              "0.7 CPU-min, 0.9 min wall, load 3.8, at 15ad936, beside another generator"),
    Generator("deploy_array_impact_rule", (PY, "experiments/deploy_array_impact_rule.py"),
              ("docs/deploy_array.md [impact-velocity-rule]",), 3.6,
              "3 CPU-min, 3.6 min wall, load 3.9, at 15ad936, beside another generator"),
    Generator("robustness", (PY, "experiments/robustness.py", "all"),
              ("docs/robustness.md [robustness-impact]", "docs/robustness.md [robustness-deploy]",
               "docs/robustness.md [robustness-long]"), 20.9,
              "20.9 CPU-min, 14.4 min wall, load 1.7, at 15ad936, beside another generator",
              results="results/robustness"),
    Generator("identification", (PY, "experiments/identification.py", "--regenerate", "--rerun"),
              (f"{I} [identification]",), 17.3,
              "17.3 CPU-min, 14.3 min wall, load 3.7, at 15ad936, beside another generator"),
    Generator("identification_landscape", (PY, "experiments/identification_landscape.py"),
              (f"{I} [identification_landscape]",), 0.5,
              "0.5 CPU-min, 0.5 min wall, load 3.5, at 15ad936, beside another generator"),
    Generator("identification_independent",
              (PY, "experiments/identification_independent.py", "--rerun"),
              (f"{I} [identification_independent]",), 2.5,
              "2.3 CPU-min, 2.5 min wall, load 2.9, at 15ad936, beside another generator"),
    Generator("identification_solvers", (PY, "experiments/identification_solvers.py", "--rerun"),
              (f"{I} [identification_solvers]",), 4,
              "2.8 CPU-min, 4 min wall, load 4.6, at 15ad936, beside another generator"),
    Generator("gradcheck_lock_time", (PY, "experiments/gradcheck_lock_time.py"),
              (f"{I} [gradcheck_lock_time]",), 5.7,
              "3.7 CPU-min, 5.7 min wall, load 4.2, at 15ad936, beside another generator"),
    Generator("gradient_sensitivity", (PY, "experiments/gradient_sensitivity.py"),
              (f"{I} [gradient_sensitivity]",), 1.9,
              "1.6 CPU-min, 1.9 min wall, load 3.1, at 15ad936, beside another generator"),
    Generator("gradient_horizon", (PY, "experiments/gradient_horizon.py"),
              (f"{I} [gradient_horizon]",), 3.3,
              "3.1 CPU-min, 3.3 min wall, load 4.8, at 15ad936, beside another generator"),
    Generator("design_study", (PY, "experiments/design_study.py", "all"), ("docs/design.md",),
              3.2,
              "3.2 CPU-min, 3.2 min wall, load 3.3, at 15ad936, beside another generator",
              results="results/design_study"),
    Generator("paper_study", (PY, "experiments/paper_study.py", "--rerun"),
              ("docs/paper_study.md",), 16.1,
              "16.1 CPU-min, 12.7 min wall, load 3.2, at 15ad936, beside another generator"),
)  # fmt: skip


def split(spec: str) -> tuple[str, str | None]:
    """`"page [block]"` -> (page, block); a whole page -> (page, None)."""
    page, _, block = spec.partition(" [")
    return page, block.rstrip("]") or None


def stale(generator: Generator, root: str = ROOT) -> list[str]:
    """Why the pages or blocks a generator writes are stale (empty: all fresh)."""
    problems = []
    for spec in generator.pages:
        page, block = split(spec)
        with open(os.path.join(root, page), encoding="utf-8") as fh:
            text = pages.part(fh.read(), block)
        found = ["missing"] if text is None else pages.page_problems(root, text)
        problems += [f"{spec}: {p.splitlines()[0]}" for p in found]
    return problems


def move_aside(folder: str) -> None:
    """A generator's stored runs, renamed out of its way (never deleted)."""
    path = os.path.join(ROOT, folder)
    if os.path.isdir(path):
        target = f"{path}.old-{time.strftime('%Y%m%d-%H%M%S')}"
        os.rename(path, target)
        print(f"[pages] moved {folder} aside to {os.path.relpath(target, ROOT)}", flush=True)


def _env() -> dict:
    """A generator's environment: this one with the checkout on PYTHONPATH."""
    path = os.pathsep.join(filter(None, [ROOT, os.environ.get("PYTHONPATH")]))
    return {**os.environ, "PYTHONPATH": path}


def run(generator: Generator) -> int:
    """Run one generator (its pages are written even when it exits non-zero: a fit that misses
    its criterion says so on the page); its exit status."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(generator.argv, cwd=os.path.join(ROOT, generator.cwd), env=_env())
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime) / 60
    _report(generator, done.returncode, 60 * cpu, time.perf_counter() - start)
    return done.returncode


def _report(generator: Generator, code: int, cpu_s: float, wall_s: float) -> None:
    print(f"[pages] {generator.name}: exit {code}, {cpu_s / 60:.1f} CPU-min, "
          f"{wall_s / 60:.1f} min wall, load {os.getloadavg()[0]:.1f}", flush=True)  # fmt: skip


def _pages_of(generator: Generator) -> set[str]:
    return {split(spec)[0] for spec in generator.pages}


def ready(chosen, index: int, running: set[int], finished: set[int]) -> bool:
    """Whether generator `chosen[index]` may start now (`--jobs`): every earlier one that
    writes one of its pages, and every earlier `alone` one, has finished; an `alone` one
    starts only when nothing runs; nothing starts beside a running `alone` one."""
    g = chosen[index]
    if any(chosen[i].alone for i in running):
        return False
    if g.alone and running:
        return False
    for i in range(index):
        if i in finished:
            continue
        if chosen[i].alone or _pages_of(chosen[i]) & _pages_of(g):
            return False
    return True


def schedule(chosen, jobs: int, start, wait) -> list[str]:
    """Run the generators `chosen`, up to `jobs` at once where `ready` allows, in the list's
    order otherwise; `start(generator)` starts one and returns a handle, `wait(handles)`
    blocks until one of them ends and returns `(handle, exit status)`. Returns the names of
    those that exited non-zero."""
    pending, running, finished, failed = list(range(len(chosen))), {}, set(), []
    while pending or running:
        for index in list(pending):
            if len(running) >= jobs:
                break
            if ready(chosen, index, set(running), finished):
                pending.remove(index)
                running[index] = start(chosen[index])
        if not running:  # nothing could start: a bug in `ready`, not a wait for ever
            raise RuntimeError(f"no generator can start: {[chosen[i].name for i in pending]}")
        handle, code = wait(list(running.values()))
        index = next(i for i, h in running.items() if h is handle)
        del running[index]
        finished.add(index)
        if code != 0:
            failed.append(chosen[index].name)
    return failed


class _Child:
    """A generator running as a child process, its output in `log`."""

    def __init__(self, generator: Generator, log_dir: str):
        self.generator = generator
        self.log = os.path.join(log_dir, f"{generator.name}.log")
        self.began = time.perf_counter()
        with open(self.log, "w", encoding="utf-8") as out:
            self.process = subprocess.Popen(
                generator.argv, cwd=os.path.join(ROOT, generator.cwd), env=_env(), stdout=out,
                stderr=subprocess.STDOUT,
            )  # fmt: skip
        print(f"[pages] {generator.name}: started (log {os.path.relpath(self.log, ROOT)})",
              flush=True)  # fmt: skip


def _wait_any(children: list[_Child]) -> tuple[_Child, int]:
    """The first of `children` to end, its exit status, and its own CPU time reported
    (`os.wait4`: the child's and its descendants' rusage, not the other children's)."""
    while True:
        # Each of ours by its pid (not any child: a process may have others, whose owners
        # would lose them), a tenth of a second apart: generators run for minutes.
        for child in children:
            pid, status, usage = os.wait4(child.process.pid, os.WNOHANG)
            if pid == 0:
                continue
            code = os.waitstatus_to_exitcode(status)
            child.process.returncode = code
            cpu = usage.ru_utime + usage.ru_stime
            _report(child.generator, code, cpu, time.perf_counter() - child.began)
            if code != 0:
                print(f"[pages] {child.generator.name}: see {child.log}", flush=True)
            return child, code
        time.sleep(0.1)


def run_parallel(chosen, jobs: int, keep_results: bool) -> list[str]:
    """`schedule` with child processes, their output in results/pages-logs/."""
    log_dir = os.path.join(ROOT, "results", "pages-logs")
    os.makedirs(log_dir, exist_ok=True)

    children = []

    def start(generator):
        if generator.results and not keep_results:
            move_aside(generator.results)
        children.append(_Child(generator, log_dir))
        return children[-1]

    try:
        return schedule(chosen, jobs, start, _wait_any)
    except KeyboardInterrupt:
        # A stopped generator may have written some of its files: `git status` shows them.
        running = [c for c in children if c.process.poll() is None]
        for child in running:
            child.process.terminate()
        for child in running:
            child.process.wait()
        names = ", ".join(c.generator.name for c in running) or "none"
        raise SystemExit(
            f"[pages] interrupted (Ctrl-C): stopped {names}; `git status` shows what they wrote"
        ) from None


def select(only=(), quick=False, stale_only=False):
    names = {g.name for g in GENERATORS}
    unknown = sorted(set(only) - names)
    if unknown:
        raise SystemExit(f"unknown generator(s) {unknown}; choose from {sorted(names)}")
    chosen = [g for g in GENERATORS if not only or g.name in only]
    chosen = [g for g in chosen if not quick or g.minutes <= QUICK_MINUTES]
    return [g for g in chosen if not stale_only or stale(g)]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", default=(), metavar="NAME", help="these generators")
    ap.add_argument("--quick", action="store_true",
                    help=f"only generators under {QUICK_MINUTES:g} min each")  # fmt: skip
    ap.add_argument("--stale", action="store_true", help="only generators of stale pages")
    ap.add_argument(
        "--keep-results",
        action="store_true",
        help="let the long studies reuse their stored runs (recorded as runs_at)",
    )
    ap.add_argument("--list", action="store_true", help="list (with why stale) and stop")
    ap.add_argument("--jobs", type=int, default=1, metavar="N",
                    help="run up to N generators at once where they share no page (default 1; "
                         "`make bench` always alone)")  # fmt: skip
    args = ap.parse_args(argv)
    if args.jobs < 1:
        ap.error(f"--jobs {args.jobs} is invalid: it must be ≥ 1")
    chosen = select(args.only, args.quick, args.stale)
    total = sum(g.minutes for g in chosen)
    print(f"[pages] {len(chosen)} generators, about {total:.0f} min measured", flush=True)
    for g in chosen:
        why = stale(g)
        print(f"  {g.name:32s} {g.minutes:5.1f} min ({g.measured}): {', '.join(g.pages)}; "
              + ("stale: " + "; ".join(why) if why else "fresh"))  # fmt: skip
    if args.list:
        return 0
    if args.jobs > 1:
        failed = run_parallel(chosen, args.jobs, args.keep_results)
        if failed:
            print(f"[pages] exited non-zero (their pages say why): {', '.join(failed)}")
        return 1 if failed else 0
    failed = []
    for g in chosen:
        if g.results and not args.keep_results:
            move_aside(g.results)
        if run(g) != 0:
            failed.append(g.name)
    if failed:
        print(f"[pages] exited non-zero (their pages say why): {', '.join(failed)}")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
