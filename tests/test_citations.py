"""Citations resolve: what a page, a comment, a docstring or a test names still exists.

Scanned: README.md and docs/ (pages), jaxdeploy/, benchmarks/, experiments/, tools/ and
tests/ (their comments, docstrings and strings: code that names a gone module fails when it
runs). Three kinds of citation:

* a **commit** (`at 61e187c`, `commit 9528742`, any hex word of 7–40 characters with a letter
  and a digit): it must be an ancestor of HEAD (a commit rebased away is no evidence);
* a **docs section**: `docs/x.md, "Heading"` or `x.md ("Heading"` (the cited text starts a
  heading of that page), `docs/x.md §7` (a heading numbered 7), a link `x.md#anchor` or
  `#anchor` (GitHub's slug of a heading);
* a **module or constant**: `jaxdeploy.a.b` (a module, or a name defined at the top of one),
  and `module.CONSTANT` where `module` is one of ours (`saddle_point.UNROLLED_MAX_SIZE`).

Each check is proved on a deliberately stale fixture below (a dead commit, a dead section, a
gone module and constant); the real files are expected to pass. This file itself is not
scanned (its fixtures are dead on purpose). Git and text only: seconds.
"""

from __future__ import annotations

import ast
import bisect
import functools
import io
import pathlib
import re
import subprocess
import tokenize

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
SCANNED = (
    "README.md",
    "docs/**/*.md",
    "tests/**/*.md",
    "jaxdeploy/**/*.py",
    "benchmarks/**/*.py",
    "experiments/**/*.py",
    "tools/**/*.py",
    "tests/**/*.py",
)
SELF = pathlib.Path(__file__).resolve()
# Hex words that are examples, not citations (the label format's docstring, tests' fakes).
EXAMPLES = re.compile(r"abc1234567|0123456789")

HEX = re.compile(r"(?<![\w.\-+/])([0-9a-f]{7,40})(?![\w])(?![.\-+]\d)")
# A number-only word is a commit only after a word that introduces one.
NUMERIC_COMMIT = re.compile(
    r"\b(?:commit|commits|at|before|after|since|show)\s+`?(\d{7,12})\b(?![.,]\d|\s*(?:s|ms|µs|steps|Hz|N)\b)"
)
SECTION = re.compile(
    r"(?:docs/)?([a-z_]+)\.md(?:,\s*|\s+\()[\"“]([^\"”]{3,80})[\"”]|(?:docs/)?([a-z_]+)\.md\s+§\s?(\d+)"
)
ANCHOR = re.compile(r"\]\((?:([a-z_]+)\.md)?#([a-z0-9\-]+)\)")
DOTTED = re.compile(r"(?<![\w.])jaxdeploy((?:\.[A-Za-z_][A-Za-z0-9_]*)+)")
CONSTANT = re.compile(r"(?<![\w.])([a-z_][a-z0-9_]*)\.([A-Z][A-Z0-9]*_[A-Z0-9_]+)\b")


def _git(root, *args):
    return subprocess.run(["git", *args], cwd=root, capture_output=True, text=True)


def scanned_files(root):
    files = {p for pattern in SCANNED for p in pathlib.Path(root).glob(pattern)}
    return sorted(p for p in files if p.resolve() != SELF and ".venv" not in p.parts)


STRING_TOKENS = {tokenize.STRING, getattr(tokenize, "FSTRING_MIDDLE", tokenize.STRING)}
QUOTES = re.compile(r"^[rbfuRBFU]*(\"\"\"|\'\'\'|\"|\')(.*)\1$", flags=re.S)


def prose(path: pathlib.Path) -> str:
    """A page's text; a module's comments and string contents (quotes dropped), one per
    line, with line breaks (and a comment's `#`) folded into spaces, so that a citation
    wrapped over two lines is found."""
    text = path.read_text(encoding="utf-8")
    if path.suffix == ".py":
        parts = []
        for token in tokenize.generate_tokens(io.StringIO(text).readline):
            if token.type == tokenize.COMMENT:
                parts.append(token.string)
            elif token.type in STRING_TOKENS:
                quoted = QUOTES.match(token.string)
                parts.append(quoted.group(2) if quoted else token.string)
        text = "\n".join(parts)
    return re.sub(r"\s*\n\s*(?:#\s*)?", " ", text)


# --- commits -------------------------------------------------------------------------------


def history(root) -> list[str]:
    """The full hashes of HEAD and its ancestors, sorted (for prefix look-up)."""
    return sorted(_git(root, "rev-list", "HEAD").stdout.split())


def cited_commits(text) -> set[str]:
    found = {m for m in HEX.findall(text) if re.search(r"[a-f]", m) and re.search(r"\d", m)}
    found |= set(NUMERIC_COMMIT.findall(text))
    return {c for c in found if not EXAMPLES.match(c)}


def in_history(commit, commits) -> bool:
    i = bisect.bisect_left(commits, commit)
    return i < len(commits) and commits[i].startswith(commit)


# --- docs sections -------------------------------------------------------------------------


def headings(page: pathlib.Path) -> list[str]:
    if not page.exists():
        return []
    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.S)
    return [m.strip() for m in re.findall(r"^#{1,6}\s+(.*)$", text, flags=re.M)]


def _plain(heading):
    return re.sub(r"\s+", " ", heading.replace("`", "").replace("*", "")).strip().lower()


def slug(heading):
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces as hyphens."""
    return re.sub(r"[^\w\- ]", "", _plain(heading)).replace(" ", "-")


def section_exists(page, cited) -> bool:
    return any(_plain(h).startswith(_plain(cited)) for h in headings(page))


def numbered_section_exists(page, number) -> bool:
    return any(re.match(rf"§?\s*{number}\b", h) for h in headings(page))


# --- modules and constants -----------------------------------------------------------------


@functools.cache
def top_level_names(path: pathlib.Path) -> frozenset[str]:
    """Names a module defines at its top (assignments, functions, classes, imports)."""
    names = set()
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            names.add(node.name)
        elif isinstance(node, ast.Assign | ast.AnnAssign | ast.AugAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for target in targets:
                names |= {n.id for n in ast.walk(target) if isinstance(n, ast.Name)}
        elif isinstance(node, ast.Import | ast.ImportFrom):
            names |= {(a.asname or a.name).split(".")[0] for a in node.names}
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets
        ):  # names a lazy `__getattr__` provides are listed there
            names |= {e.value for e in ast.walk(node.value) if isinstance(e, ast.Constant)}
    return frozenset(names)


def module_file(root, parts):
    """The file of module `parts` (a package's `__init__.py`), or None."""
    base = pathlib.Path(root).joinpath(*parts)
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.exists():
            return candidate
    return None


def dotted_problem(root, dotted) -> str | None:
    """Why `jaxdeploy.<dotted>` does not resolve (None when it does): the longest prefix
    that is a module, then a name defined at its top (further attributes are not checked)."""
    parts = ["jaxdeploy", *dotted.strip(".").split(".")]
    for k in range(len(parts), 0, -1):
        found = module_file(root, parts[:k])
        if found is None:
            continue
        if k == len(parts):
            return None
        name = parts[k]
        if name.startswith("__") and name.endswith("__"):
            return None  # a module attribute (__file__, __version__)
        subpackage = module_file(root, [*parts[:k], name])
        if name in top_level_names(found) or subpackage is not None:
            return None
        return f"{'.'.join(parts[:k])} has no {name}"
    return f"no module {'.'.join(parts[:2])}"


@functools.cache
def our_modules(root) -> dict[str, list[pathlib.Path]]:
    """Our modules by their last name (`saddle_point` → jaxdeploy/mechanism/saddle_point.py)."""
    modules: dict[str, list[pathlib.Path]] = {}
    for folder in ("jaxdeploy", "benchmarks", "experiments", "tests", "tools"):
        for path in pathlib.Path(root, folder).rglob("*.py"):
            name = path.parent.name if path.name == "__init__.py" else path.stem
            modules.setdefault(name, []).append(path)
    return modules


def constant_problem(root, module, constant) -> str | None:
    files = our_modules(str(root)).get(module)
    if not files or module in ("self", "cls"):
        return None  # not one of ours (np.PI, os.O_RDONLY): not checked
    if any(constant in top_level_names(f) for f in files):
        return None
    return f"{module}.{constant}: no module named {module} defines {constant}"


# --- the scan ------------------------------------------------------------------------------


def dead_citations(root, files=None) -> list[str]:
    """Every citation in `files` (default: the scanned ones) that does not resolve."""
    root = pathlib.Path(root)
    commits = history(root)
    dead = []
    for path in files if files is not None else scanned_files(root):
        text = prose(path)
        where = path.relative_to(root)
        dead += [
            f"{where}: commit {c} is not an ancestor of HEAD"
            for c in sorted(cited_commits(text))
            if not in_history(c, commits)
        ]
        for page, cited, page_n, number in SECTION.findall(text):
            if page:
                if not section_exists(root / "docs" / f"{page}.md", cited):
                    dead.append(f'{where}: docs/{page}.md has no section "{cited}"')
            elif not numbered_section_exists(root / "docs" / f"{page_n}.md", number):
                dead.append(f"{where}: docs/{page_n}.md has no section §{number}")
        for page, anchor in ANCHOR.findall(text):
            target = root / "docs" / f"{page}.md" if page else path
            if anchor not in {slug(h) for h in headings(target)}:
                dead.append(f"{where}: {target.relative_to(root)} has no anchor #{anchor}")
        for dotted in sorted(set(DOTTED.findall(text))):
            problem = dotted_problem(root, dotted)
            if problem:
                dead.append(f"{where}: jaxdeploy{dotted}: {problem}")
        for module, constant in sorted(set(CONSTANT.findall(text))):
            problem = constant_problem(root, module, constant)
            if problem:
                dead.append(f"{where}: {problem}")
    return dead


def _history_or_skip(root=ROOT):
    if _git(root, "rev-parse", "--is-inside-work-tree").stdout.strip() != "true":
        pytest.skip("not a git checkout: the cited commits cannot be looked up")
    if _git(root, "rev-parse", "--is-shallow-repository").stdout.strip() == "true":
        pytest.skip("shallow clone: cited commits may be missing from it")


def test_every_citation_resolves():
    _history_or_skip()
    dead = dead_citations(ROOT)
    assert not dead, "citations that do not resolve:\n" + "\n".join(dead)


# --- each check on a deliberately stale fixture --------------------------------------------


@pytest.fixture
def tree(tmp_path):
    """A small checkout: a package with a module and a constant, a page with sections, two
    commits on main and one rebased away (made on a branch, then the branch deleted)."""
    if _git(tmp_path, "init", "-q").returncode != 0:
        pytest.skip("git is not available")
    pkg = tmp_path / "jaxdeploy" / "contact"
    pkg.mkdir(parents=True)
    (tmp_path / "jaxdeploy" / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("from .damping import LAW\n")
    (pkg / "damping.py").write_text("DEFAULT_FLOOR = 1e-4\nLAW = 'x'\n\ndef chi():\n    pass\n")
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "contact.md").write_text(
        "# Contact\n\n## Roughness helpers\n\ntext\n\n## 7. Latch and the frequency\n"
    )

    def commit(message):
        _git(tmp_path, "add", "-A")
        _git(tmp_path, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", message)
        return _git(tmp_path, "rev-parse", "HEAD").stdout.strip()

    live = commit("first")
    _git(tmp_path, "checkout", "-qb", "gone")
    (tmp_path / "docs" / "extra.md").write_text("# extra\n")
    dead = commit("rebased away")
    # A word of hex letters alone ("bcddcef") is prose, not a commit, to the scan: with a
    # hash that happens to start so (about 1 in 1000), the checks below had nothing to find.
    for attempt in range(100):
        if any(c.isdigit() for c in dead[:7]):
            break
        _git(tmp_path, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q", "--amend",
             "-m", f"rebased away ({attempt})")  # fmt: skip
        dead = _git(tmp_path, "rev-parse", "HEAD").stdout.strip()
    _git(tmp_path, "checkout", "-q", "-")
    _git(tmp_path, "branch", "-qD", "gone")
    return tmp_path, live, dead


def _scan(root, text, suffix=".md"):
    path = root / f"citing{suffix}"
    path.write_text(text)
    return dead_citations(root, [path])


def test_a_commit_rebased_away_is_dead(tree):
    root, live, dead = tree
    assert _scan(root, f"Generated at commit {live[:10]}; fits at {live[:7]}.\n") == []
    assert _scan(root, f"Generated at commit {dead[:10]}.\n") == [
        f"citing.md: commit {dead[:10]} is not an ancestor of HEAD"
    ]
    assert _scan(root, f"# measured at {dead[:7]}, 585k steps\n", ".py") != []
    # A number-only word is a commit only after a word that introduces one, and floats and
    # examples are not commits.
    assert _scan(root, "K = 6.6102e10 N, 1.362057e-5 s, at 1000000 steps, `abc1234567`\n") == []
    assert _scan(root, "measured at 2620739, load 8\n") == [
        "citing.md: commit 2620739 is not an ancestor of HEAD"
    ]


def test_a_section_that_is_gone_is_dead(tree):
    root, _, _ = tree
    alive = (
        'See docs/contact.md, "Roughness helpers"; contact.md ("Roughness helpers"); '
        "docs/contact.md §7; [h](contact.md#roughness-helpers).\n"
    )
    assert _scan(root, alive) == []
    # Wrapped over two comment lines, as in a docstring or a `#` comment.
    assert _scan(
        root, '# how friction depends on it (docs/contact.md,\n# "Roughness\n# couplings")\n', ".py"
    ) == [  # noqa: E501
        'citing.py: docs/contact.md has no section "Roughness couplings"'
    ]
    assert _scan(root, 'docs/design.md, "Gradient-based optimum"\n') == [
        'citing.md: docs/design.md has no section "Gradient-based optimum"'
    ]
    assert _scan(root, "docs/contact.md §9\n") == ["citing.md: docs/contact.md has no section §9"]
    assert _scan(root, "[h](contact.md#roughness-couplings)\n") == [
        "citing.md: docs/contact.md has no anchor #roughness-couplings"
    ]


def test_a_module_or_constant_that_is_gone_is_dead(tree):
    root, _, _ = tree
    alive = (
        "as jaxdeploy.contact.damping.DEFAULT_FLOOR, jaxdeploy.contact.LAW, "
        "jaxdeploy.contact.damping.chi, damping.DEFAULT_FLOOR, np.SOME_CONSTANT\n"
    )
    assert _scan(root, alive, ".py") == []
    assert _scan(root, "# m/s, as jaxdeploy.contact.damping.VELOCITY_FLOOR\n", ".py") == [
        "citing.py: jaxdeploy.contact.damping.VELOCITY_FLOOR: jaxdeploy.contact.damping has "
        "no VELOCITY_FLOOR"
    ]
    assert _scan(root, "`jaxdeploy.lanes` refills lanes\n") == [
        "citing.md: jaxdeploy.lanes: jaxdeploy has no lanes"
    ]
    assert _scan(root, "(damping.VELOCITY_FLOOR = 1e-4)\n") == [
        "citing.md: damping.VELOCITY_FLOOR: no module named damping defines VELOCITY_FLOOR"
    ]
