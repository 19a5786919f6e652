"""The README's tour, timed as a newcomer meets it (`python -m benchmarks tour`; `make bench`
runs it too).

Every command of the README's "A five-minute tour" runs in order, with bash, in a fresh folder
that holds only a link to `examples/`, with an empty compilation cache (`JAXDEPLOY_CACHE_DIR`
in a temporary folder, so the first simulation compiles and later ones reuse what earlier ones
cached, as on a new machine). Each command's wall time and the CPU time of its process tree
(`resource.getrusage(RUSAGE_CHILDREN)`, user + system, which other jobs' load does not inflate)
replace the `Time:` line after its block, with the phases of the `summary.json` it wrote; the
section's provenance comment records commit, machine and load, so that
`tests/test_page_freshness.py` fails once the package changes after the measurement.

The README's parser (`sections`, `commands`) is shared with `tests/test_readme.py`, which runs
the same commands for correctness.
"""

from __future__ import annotations

import glob
import json
import os
import re
import resource
import shlex
import subprocess
import sys
import tempfile
import time

from . import provenance

TOUR = "A five-minute tour"
TIME_LINE = re.compile(r"^Time: .*$", flags=re.M)
# What the tour runs: the package and the example data it reads.
MEASURES = ["examples", "jaxdeploy"]


def timed(command: str) -> bool:
    """The tour times its `jaxdeploy` commands; the rest (`source .venv/bin/activate`: the
    environment's bin is put first on PATH instead; `ls`) only prepare or look."""
    words = shlex.split(command, comments=True)
    return bool(words) and words[0] == "jaxdeploy"


def commands(body: str) -> list[str]:
    """The commands of a ```bash block: one per line, a trailing backslash continues a line,
    comment lines dropped (bash drops trailing comments itself)."""
    out, current = [], ""
    for line in body.splitlines():
        current += line.rstrip()
        if current.endswith("\\"):
            current = current[:-1] + " "
            continue
        if current.strip() and not current.lstrip().startswith("#"):
            out.append(current.strip())
        current = ""
    return out


def sections(text: str) -> list[tuple[str, list[tuple[str, list[str], str]]]]:
    """`[(section title, [blocks])]`, each block `(language, [commands], text after it)`; a
    non-bash block's "commands" is its body."""
    out, title = [], ""
    for part in re.split(r"^(##+ .*)$", text, flags=re.M):
        if part.startswith("##"):
            title = part.lstrip("#").strip()
            continue
        blocks = []
        for match in re.finditer(r"```(\w+)\n(.*?)```(.*?)(?=```|\Z)", part, flags=re.S):
            language, body, after = match.groups()
            blocks.append((language, commands(body) if language == "bash" else [body], after))
        out.append((title, blocks))
    return out


def _seconds(x: float) -> str:
    return f"{x:.2g} s" if x < 10 else f"{x:.0f} s"


def _phases(folder: str) -> dict | None:
    """The `phases` of the `summary.json` a command wrote, if it wrote one."""
    path = os.path.join(folder, "summary.json")
    if not os.path.exists(path):
        return None
    with open(path, encoding="utf-8") as f:
        phases = json.load(f).get("phases")
    return phases if isinstance(phases, dict) and phases else None


def run_tour(readme: str, root: str) -> list[dict]:
    """Run the tour's commands in order; per bash block, `{"commands": [{command, wall_s,
    cpu_s, phases}]}`. Raises if a command fails (a tour that does not run has no times)."""
    tour = dict(sections(readme)).get(TOUR)
    if tour is None:
        raise RuntimeError(f"README has no '## {TOUR}' section")
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        cwd = os.path.join(tmp, "tour")
        os.makedirs(cwd)
        os.symlink(os.path.join(root, "examples"), os.path.join(cwd, "examples"))
        env = dict(os.environ)
        env["PATH"] = os.path.dirname(sys.executable) + os.pathsep + env.get("PATH", "")
        env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
        env["JAXDEPLOY_CACHE_DIR"] = os.path.join(tmp, "cache")
        for language, block, _ in tour:
            if language != "bash":
                continue
            measured = []
            for command in block:
                if not timed(command):
                    continue
                before = set(glob.glob(os.path.join(cwd, "results", "*", "*")))
                cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
                start = time.perf_counter()
                done = subprocess.run(["bash", "-c", command], cwd=cwd, env=env,
                                      capture_output=True, text=True)  # fmt: skip
                wall = time.perf_counter() - start
                cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
                if done.returncode != 0:
                    raise RuntimeError(
                        f"tour command `{command}` exited {done.returncode}:\n"
                        f"{done.stdout[-2000:]}\n{done.stderr[-2000:]}"
                    )
                new = sorted(set(glob.glob(os.path.join(cwd, "results", "*", "*"))) - before)
                measured.append(
                    {
                        "command": command,
                        "wall_s": wall,
                        "cpu_s": (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime),
                        "phases": _phases(new[0]) if len(new) == 1 else None,
                    }
                )
                print(f"  {wall:7.1f} s  {command}", flush=True)
            if measured:
                out.append({"commands": measured})
    return out


def time_line(block: dict) -> str:
    """`Time: ...` for one block: wall and CPU per command, and the phases it recorded."""
    parts = []
    for c in block["commands"]:
        text = f"{_seconds(c['wall_s'])} wall, {_seconds(c['cpu_s'])} CPU"
        if c["phases"]:
            text += " (phases: " + ", ".join(
                f"{name.removesuffix('_s')} {_seconds(float(s))}"
                for name, s in c["phases"].items()
                if isinstance(s, int | float)
            ) + ")"  # fmt: skip
        if len(block["commands"]) > 1:
            text = f"`{c['command']}` {text}"
        parts.append(text)
    return "Time: " + "; ".join(parts) + "."


def rewrite(readme: str, blocks: list[dict], record: dict) -> str:
    """The README with the tour's `Time:` lines and its provenance replaced. Every timed
    block of the tour must be followed by one `Time:` line before the next block."""
    head, sep, rest = readme.partition(f"## {TOUR}\n")
    if not sep:
        raise RuntimeError(f"README has no '## {TOUR}' section")
    nxt = re.search(r"^## ", rest, flags=re.M)
    tour, tail = (rest[: nxt.start()], rest[nxt.start() :]) if nxt else (rest, "")
    pieces = re.split(r"(```\w+\n.*?```)", tour, flags=re.S)
    # The text after each bash block that runs something the tour times.
    after_timed = [
        i
        for i in range(2, len(pieces), 2)
        if pieces[i - 1].startswith("```bash")
        and any(map(timed, commands(pieces[i - 1].split("\n", 1)[1].rsplit("```", 1)[0])))
    ]
    if any(len(TIME_LINE.findall(pieces[i])) != 1 for i in after_timed):
        raise RuntimeError("each timed tour block needs exactly one 'Time:' line after it")
    if len(after_timed) != len(blocks):
        raise RuntimeError(f"{len(blocks)} timed blocks measured, {len(after_timed)} in the tour")
    for i, block in zip(after_timed, blocks, strict=True):
        line = time_line(block)
        pieces[i] = TIME_LINE.sub(lambda _, line=line: line, pieces[i])
    tour = "".join(pieces)
    m = record["machine"]
    stamp = (
        "Times: `make bench` (`python -m benchmarks tour`) at commit "
        f"`{record['commit'][:12]}` on {m['cpu_model']} ({m['cpu_count']} cores), load average "
        f"{record['load_start_1min']:.1f} at the start and {record['load_end_1min']:.1f} at the "
        "end, from an empty compilation cache, in this order; CPU is user + system time of the "
        "command's processes.\n\n" + provenance.page_comment(record)
    )
    stamp_pattern = re.compile(r"^Times: .*?<!-- provenance \{.*?\} -->", flags=re.M | re.S)
    if not stamp_pattern.search(tour):
        raise RuntimeError("the tour section has no 'Times: ... <!-- provenance -->' paragraph")
    tour = stamp_pattern.sub(lambda _: stamp, tour)
    return head + sep + tour + tail


def main(readme_path: str = "README.md", *, allow_dirty: bool = False) -> int:
    root = os.path.dirname(os.path.abspath(readme_path))
    with open(readme_path, encoding="utf-8") as f:
        text = f.read()
    record = provenance.start(MEASURES, allow_dirty=allow_dirty, root=root)
    began = time.perf_counter()
    blocks = run_tour(text, root)
    record = provenance.finish(record)
    record["wall_s"] = time.perf_counter() - began
    from jaxdeploy.io import atomic_write_bytes

    atomic_write_bytes(readme_path, rewrite(text, blocks, record).encode("utf-8"))
    print(f"rewrote the tour's times in {readme_path} ({record['wall_s']:.0f} s)")
    return 0
