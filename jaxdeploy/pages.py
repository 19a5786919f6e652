"""What a generated docs page records about how it was made, and reading it back.

Every script that writes numbers or figures into a page (`experiments/*.py`,
`tests/verify_mechanics.py`, `tests/independent/*report.py`, `make bench`) records, in each block
it writes, one machine-readable line

    <!-- provenance {"commit": ..., "dirty": false, "measures": [...], "command": ..., ...} -->

with the commit the numbers were made at (`git rev-parse HEAD`), whether tracked files outside
the generated pages differed from it (`dirty`: a page is made from committed code only, so a
dirty tree is refused unless the caller allows it, and then the page says so and fails the
freshness test), the command that regenerates the block, and the paths it *measures*: the
modules whose change would move its numbers, declared narrowly by the generator so that an
unrelated change does not make the page stale. `tests/test_page_freshness.py` fails when a
commit after the recorded one changed a measured path.

The generated pages themselves (docs/, README.md) do not count as changes: `make pages` runs
the generators one after another, each writing its page, on one commit.
"""

from __future__ import annotations

import json
import os
import re
import resource
import subprocess
import time

from .io import changed_code, machine_description, replace_block

PATTERN = re.compile(r"<!-- provenance (\{.*?\}) -->", flags=re.S)
ALLOW_DIRTY = "JAXDEPLOY_PAGES_ALLOW_DIRTY"  # set to 1 to write a page from uncommitted code


def git(*args: str, root: str = ".") -> str:
    """git's output without its trailing newline (leading blanks kept: `status --porcelain`
    puts the status in the first two columns)."""
    return subprocess.run(
        ["git", *args], cwd=root, capture_output=True, text=True, check=True
    ).stdout.rstrip()


def checkout_root() -> str:
    """The top of the git checkout this package runs from (the pages live there)."""
    here = os.path.dirname(os.path.abspath(__file__))
    return git("rev-parse", "--show-toplevel", root=here)


def tree_state(root: str = ".") -> tuple[str, bool]:
    """`(commit, dirty)`: HEAD, and whether tracked files differ from it (untracked files
    and the generated pages, `io.GENERATED`, do not count)."""
    commit = git("rev-parse", "HEAD", root=root)
    return commit, changed_code(git("status", "--porcelain", "--untracked-files=no", root=root))


def start(
    measures: list[str], command: str, *, allow_dirty: bool | None = None, root: str | None = None
) -> dict:
    """The provenance of a page run about to start. `measures`: paths relative to the checkout
    (they must exist: a typo would hide every change from the freshness test). Refuses a dirty
    tree unless `allow_dirty` (default: the environment variable `JAXDEPLOY_PAGES_ALLOW_DIRTY`
    is 1); the page then says so and fails the freshness test."""
    root = checkout_root() if root is None else root
    missing = [p for p in measures if not os.path.exists(os.path.join(root, p))]
    if missing:
        raise FileNotFoundError(f"the page measures paths that do not exist: {missing}")
    if allow_dirty is None:
        allow_dirty = os.environ.get(ALLOW_DIRTY) == "1"
    commit, dirty = tree_state(root)
    if dirty and not allow_dirty:
        raise RuntimeError(
            "the working tree has uncommitted changes outside docs/ and README.md: commit them "
            f"first (a page is made from committed code), or set {ALLOW_DIRTY}=1 (the page is "
            "then marked dirty and fails tests/test_page_freshness.py)"
        )
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return {
        "commit": commit,
        "dirty": dirty,
        "command": command,
        "measures": sorted(measures),
        "machine": machine_description(),
        "load_start_1min": os.getloadavg()[0],
        "_t0": (time.perf_counter(), usage.ru_utime + usage.ru_stime),
    }


def finish(record: dict) -> dict:
    """`record` with the load average at the end, and the wall and CPU (user + system, this
    process and its waited-for children) seconds since `start`; a finished record is returned
    as it is (a page rewritten from stored results keeps the run's record)."""
    if "_t0" not in record:
        return record
    record = dict(record)
    wall0, cpu0 = record.pop("_t0")
    usage = [resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)]
    cpu = sum(u.ru_utime + u.ru_stime for u in usage)
    record["load_end_1min"] = os.getloadavg()[0]
    record["wall_s"] = round(time.perf_counter() - wall0, 1)
    record["cpu_s"] = round(cpu - cpu0, 1)
    return record


def comment(record: dict) -> str:
    """The machine-readable line, `<!-- provenance {json} -->`."""
    record = {k: v for k, v in record.items() if not k.startswith("_")}
    return f"<!-- provenance {json.dumps(record, sort_keys=True, default=str)} -->"


def label(record: dict) -> str:
    """`commit abc1234567` (`, uncommitted changes` when dirty), for the readable line."""
    dirty = " (uncommitted changes: not reproducible)" if record["dirty"] else ""
    return f"commit {record['commit'][:10]}{dirty}"


def stamp(record: dict) -> str:
    """A readable line saying which command and commit made the block, and the comment."""
    return (
        f"*Generated by `{record['command']}` at {label(record)}; do not edit by hand.*\n"
        + comment(record)
    )


def read_all(text: str) -> list[dict]:
    """Every provenance record in a page's text, in order."""
    return [json.loads(found) for found in PATTERN.findall(text)]


def read(text: str) -> dict | None:
    """The first provenance record in a page's text, or None."""
    records = read_all(text)
    return records[0] if records else None


def write_block(path: str, name: str, text: str, record: dict) -> None:
    """Replace the generated block `name` of the page at `path` (`io.replace_block`) with
    `text` under the stamp of `record` (finished now)."""
    replace_block(path, name, stamp(finish(record)) + "\n\n" + text.strip() + "\n")


def whole_page(text: str, record: dict) -> str:
    """A page written whole by one script: `text` with the stamp of `record` (finished now)
    after its title line."""
    title, _, body = text.partition("\n")
    return f"{title}\n\n{stamp(finish(record))}\n\n{body.lstrip()}"


# --- freshness (tests/test_page_freshness.py, `python -m tools.pages --stale`) ---------------

BLOCK = re.compile(r"<!-- BEGIN (\S+) -->(.*?)<!-- END \1 -->", flags=re.S)


def _git_ok(root: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["git", *args], cwd=root, capture_output=True, text=True)


def record_problems(root: str, record: dict) -> list[str]:
    """Why a provenance record is stale, checked against the git history at `root` (empty
    when fresh): made from a dirty tree; its commit, or the commit of a run it reused
    (`runs_at`), not an ancestor of HEAD; a measured path gone, or changed by a later
    commit."""
    if record.get("dirty"):
        return [f"made from uncommitted code (dirty tree at {record['commit'][:12]})"]
    problems = []
    measures = record["measures"]
    missing = [p for p in measures if not os.path.exists(os.path.join(root, p))]
    if missing:
        problems.append(f"it measures paths that do not exist: {missing}")
    for commit in [record["commit"], *record.get("runs_at", [])]:
        if _git_ok(root, "merge-base", "--is-ancestor", commit, "HEAD").returncode != 0:
            problems.append(f"its commit {commit[:12]} is not in this history (rebased?)")
            continue
        changes = _git_ok(root, "log", "--oneline", f"{commit}..HEAD", "--", *measures).stdout
        if changes.strip():
            problems.append(
                f"made at {commit[:12]}; these commits changed what it measures since:\n{changes}"
            )
    return problems


def page_problems(root: str, text: str) -> list[str]:
    """Why a generated page (or one block of it) is stale: a block without a record, no
    record at all, or a stale record (`record_problems`)."""
    problems = [
        f"block {name!r} has no provenance record"
        for name, body in BLOCK.findall(text)
        if read(body) is None
    ]
    records = read_all(text)
    if not records:
        problems.append("no provenance record")
    for record in records:
        problems += record_problems(root, record)
    return problems


def part(text: str, block: str | None) -> str | None:
    """The block `block` of a page's text (None if the page lacks it), or with `block` None
    the text the page's own script wrote: every generated block of other scripts removed."""
    if block is None:
        return BLOCK.sub("", text)
    for name, body in BLOCK.findall(text):
        if name == block:
            return f"<!-- BEGIN {name} -->{body}<!-- END {name} -->"
    return None


def stored(result: dict, source: str) -> dict:
    """The provenance record a stored result (`--doc-only`) was made with; a result stored
    before its generator recorded one is refused: rerun the generator."""
    if "provenance" not in result:
        raise RuntimeError(
            f"{source} records no provenance (stored before its generator recorded one): "
            "rerun without --doc-only"
        )
    return result["provenance"]
