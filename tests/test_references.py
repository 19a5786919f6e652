"""Every reference in the repository can be followed from the repository alone.

Citations point to papers (authors, year, journal, equation) or to pages under docs/; never to
background notes kept outside the repository (a design brief and literature notes, once cited by
section number). This file is the only one allowed to spell the old forms, in its own check.
"""

import pathlib
import re
import shutil
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent
OUTSIDE_NOTES = re.compile(r"\b(DESIGN|LITERATURE)" + r"(\s*§|\.md\b)")


def _tracked_text_files():
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout: the tracked files are unknown")
    names = subprocess.run(
        ["git", "ls-files", "-z"], cwd=ROOT, check=True, capture_output=True
    ).stdout.split(b"\0")
    for name in filter(None, names):
        path = ROOT / name.decode()
        if not path.is_file():
            continue
        data = path.read_bytes()
        if b"\0" in data[:8192]:
            continue  # binary (figures)
        yield path, data.decode("utf-8", errors="replace")


def test_no_citation_of_notes_outside_the_repository():
    hits = [
        f"{path.relative_to(ROOT)}:{number}: {line.strip()}"
        for path, text in _tracked_text_files()
        if path.resolve() != pathlib.Path(__file__).resolve()
        for number, line in enumerate(text.splitlines(), start=1)
        if OUTSIDE_NOTES.search(line)
    ]
    assert not hits, "cite the paper or a docs/ page instead:\n" + "\n".join(hits)


def test_the_check_recognises_the_old_citation_forms():
    for text in ("(DESIGN §2.3)", "LITERATURE §1.4", "DESIGN.md §5", "see LITERATURE.md"):
        assert OUTSIDE_NOTES.search(text), text
    for text in ("Q90_DESIGN = q", "DESIGNS", "docs/design.md"):
        assert not OUTSIDE_NOTES.search(text), text
