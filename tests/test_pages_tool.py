"""`python -m tools.pages --jobs N` (tools/pages.py `schedule`): generators that share no
page run side by side, those that share one keep the list's order, and `make bench` (it times
the machine) runs with nothing beside it."""

from __future__ import annotations

import sys

import pytest

from tools import pages as tool
from tools.pages import GENERATORS, Generator, ready, schedule


def _gen(name, *pages, alone=False):
    return Generator(name, ("true",), tuple(pages), 1.0, "test", alone=alone)


def _simulate(chosen, jobs):
    """`schedule` with instant fake processes: the order they start and end in, and how many
    ran at once at each start. Each wait ends the generator that started first."""
    log, running = [], []

    def start(g):
        running.append(g)
        log.append(("start", g.name, len(running)))
        return g

    def wait(handles):
        first = next(g for g in running if g in handles)
        running.remove(first)
        log.append(("end", first.name))
        return first, 1 if first.name == "fails" else 0

    failed = schedule(chosen, jobs, start, wait)
    return log, failed


def test_generators_that_share_no_page_run_side_by_side():
    chosen = [_gen("a", "docs/a.md"), _gen("b", "docs/b.md"), _gen("c", "docs/c.md")]
    log, failed = _simulate(chosen, 2)
    assert failed == []
    assert ("start", "b", 2) in log  # b started while a ran
    assert max(e[2] for e in log if e[0] == "start") == 2  # never more than --jobs


def test_generators_of_one_page_keep_the_lists_order():
    # verify_mechanics writes verification.md whole, then independent_report its block.
    chosen = [
        _gen("whole", "docs/v.md"),
        _gen("block", "docs/v.md [x]"),
        _gen("other", "docs/o.md"),
    ]
    log, _ = _simulate(chosen, 2)
    assert log.index(("end", "whole")) < next(i for i, e in enumerate(log) if e[1] == "block")
    assert ("start", "other", 2) in log  # the unrelated one did not wait


def test_an_alone_generator_runs_with_nothing_beside_it_and_the_later_ones_wait():
    chosen = [_gen("geometry", "docs/g.md"), _gen("bench", "docs/p.md", alone=True),
              _gen("x", "docs/x.md"), _gen("y", "docs/y.md")]  # fmt: skip
    log, _ = _simulate(chosen, 2)
    bench = log.index(("start", "bench", 1))  # started alone
    assert log.index(("end", "geometry")) < bench
    assert log[bench + 1] == ("end", "bench")  # nothing started beside it
    assert ("start", "y", 2) in log


def test_a_failing_generator_does_not_stop_the_others():
    chosen = [_gen("fails", "docs/a.md"), _gen("b", "docs/b.md"), _gen("c", "docs/a.md [k]")]
    log, failed = _simulate(chosen, 2)
    assert failed == ["fails"]
    assert ("end", "c") in log and ("end", "b") in log


def test_the_real_list_has_the_bench_alone_and_its_page_chains_ordered():
    assert [g.name for g in GENERATORS if g.alone] == ["bench"]
    names = [g.name for g in GENERATORS]
    index = {g.name: i for i, g in enumerate(GENERATORS)}
    # identification.py measures what identification_landscape.py reads: one page, in order.
    landscape = index["identification_landscape"]
    assert not ready(GENERATORS, landscape, set(), {i for i in range(landscape) if
                                                    names[i] != "identification"})  # fmt: skip
    assert ready(GENERATORS, landscape, set(), set(range(landscape)))


def test_two_children_really_run_at_once(tmp_path, monkeypatch):
    """Two generators of different pages, each of which waits (up to a minute) for the other's
    mark: both finish only if they ran side by side. Their output goes to their logs."""
    monkeypatch.setattr(tool, "ROOT", str(tmp_path))

    def meeting(me, other):
        code = (
            "import os, sys, time; open(sys.argv[1], 'w').close(); end = time.time() + 60\n"
            "while not os.path.exists(sys.argv[2]) and time.time() < end: time.sleep(0.01)\n"
            "print('met' if os.path.exists(sys.argv[2]) else 'alone'); "
            "sys.exit(0 if os.path.exists(sys.argv[2]) else 3)"
        )
        argv = (sys.executable, "-c", code, str(tmp_path / me), str(tmp_path / other))
        return Generator(me, argv, (f"docs/{me}.md",), 0.0, "test")

    failed = tool.run_parallel([meeting("a", "b"), meeting("b", "a")], 2, keep_results=True)
    assert failed == []
    for name in ("a", "b"):
        assert (tmp_path / "results" / "pages-logs" / f"{name}.log").read_text().strip() == "met"


def test_jobs_must_be_positive(capsys):
    with pytest.raises(SystemExit) as exit_:
        tool.main(["--jobs", "0", "--list"])
    assert exit_.value.code == 2 and "--jobs 0 is invalid" in capsys.readouterr().err


def test_ctrl_c_stops_the_running_generators_and_says_so(tmp_path, monkeypatch):
    """An interrupt while generators run side by side terminates them (none is left running
    behind the tool) and ends with one line naming them, not a traceback."""
    monkeypatch.setattr(tool, "ROOT", str(tmp_path))
    sleeper = Generator("sleeper", (sys.executable, "-c", "import time; time.sleep(600)"),
                        ("docs/s.md",), 0.0, "test")  # fmt: skip
    started = []

    def interrupted(children):
        started.extend(children)
        raise KeyboardInterrupt

    monkeypatch.setattr(tool, "_wait_any", interrupted)
    with pytest.raises(SystemExit) as exit_:
        tool.run_parallel([sleeper], 2, keep_results=True)
    assert "interrupted (Ctrl-C): stopped sleeper" in str(exit_.value)
    assert started and all(c.process.poll() is not None for c in started)
