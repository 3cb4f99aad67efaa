"""Every reference to the project's documents resolves, and nothing cites a document outside it.

Code, tests, tools and docs cite the pages under ``docs/`` as ``docs/NAME.md §N`` or
``docs/NAME.md §N.M`` (with continuations such as ``§1.2-1.6``, ``§5.1, §5.2`` or
``§1.2 to §1.6``). Each cited page must exist and each section number must be a numbered
heading in it (``## 5. Title``, ``## 5 Title``, ``### 5.3 Title``). Inside ``docs/*.md`` a bare
``§N`` refers to the page itself; anywhere else a bare ``§N`` is ambiguous and fails.

Also forbidden, because a user of the package cannot follow them: citations of the team's
background files (the parent directory's shared folder, the old name of the authors'
configuration page), old-style citations by document name and number without a path, and
references to issue numbers of the tracker.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SOURCE_DIRS = ("wip_gym", "controllers", "benchmarks", "tests", "tools")
THIS_FILE = Path(__file__).resolve()

NUMBER = r"\d+(?:\.\d+)*"
#: ``docs/NAME.md`` optionally followed by ``§N`` and its continuations; ``#`` and whitespace
#: may separate the page from its first section (a comment wrapped onto the next line), and a
#: Markdown link's target may follow the page (``[docs/X.md](docs/X.md) §2``).
REFERENCE = re.compile(
    rf"docs/(?P<page>[A-Za-z0-9_\-]+)\.md(?:\]\([^)\s]*\))?"
    rf"(?P<sections>(?:[\s#]*§\s*{NUMBER})"
    rf"(?:\s*(?:,|and|to|or|/)\s*§\s*{NUMBER}|-{NUMBER})*)?"
)
SECTION = re.compile(r"§\s*(" + NUMBER + r")|-(" + NUMBER + r")")
BARE_SECTION = re.compile(r"§\s*(" + NUMBER + r")")
HEADING = re.compile(r"^#+\s+(" + NUMBER + r")\.?\s+\S", re.MULTILINE)

#: (pattern, what it is): each is a reference a reader of the repository cannot follow.
FORBIDDEN: tuple[tuple[re.Pattern[str], str], ...] = (
    (re.compile(re.escape("../" + "shared")), "a path outside the repository"),
    (re.compile(re.escape("shared/" + "reference")), "the team's background folder"),
    (re.compile("krang" + "_facts", re.IGNORECASE), "the old name of docs/AUTHORS_CONFIG.md"),
    (re.compile(r"\b(?:ERRATA|DESIGN)\b\s*§?\s*\d"), "an old-style citation without a path"),
    (re.compile(r"\bissues?\s*#?\d", re.IGNORECASE), "an issue number"),
)


@dataclass(frozen=True)
class Problem:
    path: str
    line: int
    text: str
    reason: str

    def __str__(self) -> str:
        return f"{self.path}:{self.line}: {self.reason}: {self.text!r}"


def scanned_files(root: Path = ROOT) -> list[Path]:
    """Every .py file of the packages, tests and tools; docs/*.md and README.md."""
    files = [
        path
        for directory in SOURCE_DIRS
        for path in sorted((root / directory).rglob("*.py"))
        if "__pycache__" not in path.parts and path.resolve() != THIS_FILE
    ]
    files += sorted((root / "docs").glob("*.md"))
    readme = root / "README.md"
    if readme.exists():
        files.append(readme)
    return files


def headings(page: Path) -> set[str]:
    """The section numbers of a page's numbered headings (``## 5. Title`` gives ``"5"``)."""
    return set(HEADING.findall(page.read_text(encoding="utf-8")))


def _line_of(text: str, index: int) -> int:
    return text.count("\n", 0, index) + 1


def _line_text(text: str, index: int) -> str:
    start = text.rfind("\n", 0, index) + 1
    end = text.find("\n", index)
    return text[start : end if end >= 0 else len(text)].strip()


def reference_problems(text: str, where: str, docs: Path, own_page: Path | None) -> list[Problem]:
    """Dangling ``docs/NAME.md §N`` references in ``text``, and bare ``§N`` where not allowed.

    ``own_page`` is the page ``text`` comes from when it is one of the docs (its bare ``§N``
    refer to itself); ``None`` elsewhere (a bare ``§N`` is then a problem).
    """
    problems: list[Problem] = []
    cache: dict[Path, set[str]] = {}

    def sections_of(page: Path) -> set[str]:
        if page not in cache:
            cache[page] = headings(page)
        return cache[page]

    def report(index: int, reason: str) -> None:
        problems.append(Problem(where, _line_of(text, index), _line_text(text, index), reason))

    covered: list[tuple[int, int]] = []
    for match in REFERENCE.finditer(text):
        covered.append(match.span())
        page = docs / f"{match['page']}.md"
        if not page.exists():
            report(match.start(), f"no page docs/{match['page']}.md")
            continue
        for section in SECTION.finditer(match["sections"] or ""):
            number = section.group(1) or section.group(2)
            if number not in sections_of(page):
                report(match.start(), f"docs/{page.name} has no section {number}")
    for match in BARE_SECTION.finditer(text):
        if any(start <= match.start() < end for start, end in covered):
            continue
        if own_page is None:
            report(match.start(), "a section sign without a page (write docs/NAME.md §N)")
        elif match.group(1) not in sections_of(own_page):
            report(match.start(), f"docs/{own_page.name} has no section {match.group(1)}")
    return problems


def forbidden_problems(text: str, where: str) -> list[Problem]:
    """Mentions a reader of the repository cannot follow (see the module docstring)."""
    return [
        Problem(where, _line_of(text, match.start()), _line_text(text, match.start()), reason)
        for pattern, reason in FORBIDDEN
        for match in pattern.finditer(text)
    ]


def _relative(path: Path) -> str:
    return str(path.relative_to(ROOT))


def _own_page(path: Path) -> Path | None:
    return path if path.parent == ROOT / "docs" and path.suffix == ".md" else None


def _format(problems: list[Problem]) -> str:
    return f"{len(problems)} problem(s):\n" + "\n".join(str(problem) for problem in problems)


def test_the_three_cited_pages_exist_with_numbered_sections() -> None:
    assert {"1", "2", "3", "4", "5", "6"} <= headings(ROOT / "docs" / "ERRATA.md")
    assert {str(n) for n in range(1, 10)} <= headings(ROOT / "docs" / "DESIGN.md")
    assert {"1.6", "2.4", "4.3", "5.2", "5.3"} <= headings(ROOT / "docs" / "AUTHORS_CONFIG.md")


def test_every_doc_reference_resolves() -> None:
    problems = [
        problem
        for path in scanned_files()
        for problem in reference_problems(
            path.read_text(encoding="utf-8"), _relative(path), ROOT / "docs", _own_page(path)
        )
    ]
    assert not problems, _format(problems)


def test_nothing_cites_outside_the_repository_or_an_issue() -> None:
    problems = [
        problem
        for path in scanned_files()
        for problem in forbidden_problems(path.read_text(encoding="utf-8"), _relative(path))
    ]
    assert not problems, _format(problems)


# ------------------------------------------------------------------ the checker on known text
@pytest.fixture
def docs(tmp_path: Path) -> Path:
    (tmp_path / "GUIDE.md").write_text(
        "# Guide\n\n## 1. One\n\n### 1.2 One two\n\n## 3 Three\n\nSee §3 and §4.\n"
    )
    return tmp_path


@pytest.mark.parametrize(
    ("text", "dangling"),
    [
        ("docs/GUIDE.md §1", []),
        ("docs/GUIDE.md §1.2 and docs/GUIDE.md", []),
        ("[docs/GUIDE.md](docs/GUIDE.md) §3", []),
        ("[docs/GUIDE.md](docs/GUIDE.md) §4", ["no section 4"]),
        ("(docs/GUIDE.md §1, §3)", []),
        ("# wrapped docs/GUIDE.md\n    # §1.2", []),
        ("docs/GUIDE.md §2", ["no section 2"]),
        ("docs/GUIDE.md §1.2-1.3", ["no section 1.3"]),
        ("docs/GUIDE.md §1 to §5", ["no section 5"]),
        ("docs/MISSING.md §1", ["no page docs/MISSING.md"]),
        ("as said in §1", ["without a page"]),
    ],
)
def test_reference_checker_finds_what_dangles(docs: Path, text: str, dangling: list[str]) -> None:
    problems = reference_problems(text, "x.py", docs, own_page=None)
    assert len(problems) == len(dangling), problems
    for problem, reason in zip(problems, dangling, strict=True):
        assert reason in problem.reason


def test_bare_sections_inside_a_page_refer_to_it(docs: Path) -> None:
    page = docs / "GUIDE.md"
    problems = reference_problems(page.read_text(), "GUIDE.md", docs, own_page=page)
    assert [problem.reason for problem in problems] == ["docs/GUIDE.md has no section 4"]


@pytest.mark.parametrize(
    "text",
    [
        "see ../" + "shared/DESIGN.md",
        "reference/" + "krang" + "_facts.md 5.3",
        "(ERRATA" + " 5)",
        "DESIGN" + " 6's layout",
        "the speed work (issue" + " 6)",
        "Issue" + " 10's targets",
    ],
)
def test_forbidden_mentions_are_found(text: str) -> None:
    assert forbidden_problems(text, "x.py"), text


@pytest.mark.parametrize(
    "text",
    ["docs/ERRATA.md §5", "docs/DESIGN.md §6", "the issue it raises", "DESIGN.md", "errata"],
)
def test_proper_citations_are_not_forbidden(text: str) -> None:
    assert not forbidden_problems(text, "x.py"), text
