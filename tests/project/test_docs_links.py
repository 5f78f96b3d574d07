"""The documents cite only what is in the repository.

README.md, docs/*.md and every package README: each markdown link target and each backquoted path that
names a repository file or folder must exist, and no document points outside the repository
(``../shared``, the design brief's ``reference/`` notes, its letter names for contracts). Paths are taken relative to
the repository root
or to the document's own folder. Generated places (``runs/``, ``.venv/``, ``build/``) and templates
(``<machine>``, ``*``) are not checked.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
#: produced by a run or by the install, not part of a checkout
GENERATED = ("runs/", ".venv/", "build/", ".ci/")
#: file kinds a document cites; a backquoted token ending otherwise (a topic, an action name) is not a path
EXTENSIONS = (".py", ".yaml", ".yml", ".xml", ".dbc", ".md", ".png", ".pgm", ".sh", ".txt", ".toml",
              ".json", ".msg", ".srv", ".action", ".csv", ".html")
_LINK = re.compile(r"\]\(([^)\s]+)\)")
_CODE = re.compile(r"`([^`\n]+)`")
#: outside the repository: the shared design brief and its notes, and its letter names for contracts
_OUTSIDE = re.compile(
    r"\.\./shared|(?<![\w/])reference/|DESIGN(\.md| §)|tms_reference\.md|contract \[?[A-Z]\]?(?![\w])"
)


def documents() -> list[Path]:
    found = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    for pattern in ("*/README.md", "*/*/README.md"):
        found += sorted(p for p in ROOT.glob(pattern) if not p.relative_to(ROOT).parts[0].startswith("."))
    return found


def _looks_like_path(token: str) -> bool:
    if "/" not in token or " " in token or token.startswith(("http", "/", "~", "$", "-", "<")):
        return False
    if any(c in token for c in "<>*{}=:|()[],"):
        return False
    if token.startswith(GENERATED) or token.split("/", 1)[0].isupper():  # DIR/..., FILE/...: placeholders
        return False
    return token.endswith(EXTENSIONS) or token.endswith("/")


def cited_paths(text: str) -> list[tuple[int, str]]:
    """(line, path) of every link target and backquoted repository path in ``text``."""
    out = []
    for lineno, line in enumerate(text.splitlines(), 1):
        for match in _LINK.finditer(line):
            target = match.group(1).split("#", 1)[0]
            if target and not target.startswith(("http://", "https://", "mailto:")):
                out.append((lineno, target))
        for match in _CODE.finditer(line):
            token = match.group(1).strip()
            # a path inside a command (`make -C dir`, `python -m pytest tests/x.py -q`) is checked word by word
            for word in token.split():
                if _looks_like_path(word):
                    out.append((lineno, word.split("::", 1)[0]))
    return out


def missing_paths(doc: Path, root: Path = ROOT) -> list[str]:
    problems = []
    for lineno, path in cited_paths(doc.read_text(encoding="utf-8")):
        if path.startswith(GENERATED):
            continue
        if not ((root / path).exists() or (doc.parent / path).exists()):
            problems.append(f"{doc.relative_to(root)}:{lineno}: {path} does not exist")
    return problems


def outside_references(doc: Path, root: Path = ROOT) -> list[str]:
    return [f"{doc.relative_to(root)}:{lineno}: points outside the repository: {line.strip()[:100]}"
            for lineno, line in enumerate(doc.read_text(encoding="utf-8").splitlines(), 1) if _OUTSIDE.search(line)]


@pytest.mark.parametrize("doc", documents(), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_cited_path_exists(doc: Path) -> None:
    assert missing_paths(doc) == []


@pytest.mark.parametrize("doc", documents(), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_document_points_outside_the_repository(doc: Path) -> None:
    assert outside_references(doc) == []


def test_the_checks_catch_what_they_are_for(tmp_path: Path) -> None:
    """The checker itself: a missing file, a missing link target and a ``../shared`` reference are found."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "README.md").write_text("# probe\n", encoding="utf-8")
    doc = tmp_path / "docs" / "probe.md"
    doc.write_text("See `config/no_such_file.yaml` and [this](no_such_dir/x.md) and ../shared/DESIGN.md;\n"
                   "`README.md` exists, `/sim/truth/soil` is a topic, `runs/x/` is generated.\n", encoding="utf-8")
    assert sorted(missing_paths(doc, tmp_path)) == [
        "docs/probe.md:1: config/no_such_file.yaml does not exist",
        "docs/probe.md:1: no_such_dir/x.md does not exist",
    ]
    assert len(outside_references(doc, tmp_path)) == 1


def test_the_readme_keeps_the_two_commands() -> None:
    """CI (.ci/run) calls ``make test``; the README tells a user the same two commands."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert "make demo" in text and "make test" in text
