"""The docs speak of the product as it is, and the site builds with every link resolved."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: "issue 16", "issue-14", "issue #3": development history belongs in git log
ISSUE = re.compile(r"\bissues?[ -]?#?\d+", re.IGNORECASE)


def _product_files() -> list[Path]:
    files = [ROOT / "README.md", ROOT / "ARCHITECTURE.md", ROOT / "mkdocs.yml"]
    for folder, patterns in (
        ("src", ("*.py", "*.json", "*.md")),
        ("docs", ("*.md",)),
        ("configs", ("*.yaml",)),
    ):
        for pattern in patterns:
            files += sorted((ROOT / folder).rglob(pattern))
    return files


def test_no_issue_numbers_in_the_product():
    """No "issue N" in src/, docs/, configs/, README.md, ARCHITECTURE.md."""
    hits = [
        f"{path.relative_to(ROOT)}:{n}: {line.strip()[:80]}"
        for path in _product_files()
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if ISSUE.search(line)
    ]
    assert not hits, "\n".join(hits)


#: what a newcomer reads: README.md, ARCHITECTURE.md and docs/ (words as ``wc -w`` counts them)
WORD_BUDGET = 40_000


def _words(path: Path) -> int:
    return len(path.read_text(encoding="utf-8").split())


def test_docs_fit_the_word_budget():
    """README + ARCHITECTURE.md + docs/ stay under the word budget a reader can carry."""
    pages = [
        ROOT / "README.md",
        ROOT / "ARCHITECTURE.md",
        *sorted((ROOT / "docs").rglob("*.md")),
    ]
    counts = {p.relative_to(ROOT).as_posix(): _words(p) for p in pages}
    total = sum(counts.values())
    largest = ", ".join(
        f"{k} {v}" for k, v in sorted(counts.items(), key=lambda kv: -kv[1])[:5]
    )
    assert total < WORD_BUDGET, f"{total} words >= {WORD_BUDGET}; largest: {largest}"


def test_word_count_counts_what_wc_does(tmp_path: Path):
    page = tmp_path / "p.md"
    page.write_text("# Title\n\none  two\tthree\n`code` | a |\n", encoding="utf-8")
    assert 9 == _words(page)  # "#", "|" count, as in wc -w


def test_the_pattern_catches_what_it_should():
    assert ISSUE.search("the issue-16 target")
    assert ISSUE.search("(issue 14)")
    assert not ISSUE.search("a known issue with 2 trials")


def test_docs_site_builds_strict(tmp_path: Path):
    """``mkdocs build --strict``: every page in the nav, every link and anchor resolves,
    the API reference renders from the docstrings."""
    if shutil.which("mkdocs", path=str(Path(sys.executable).parent)) is None:
        pytest.fail("mkdocs is not installed: it comes with the dev extra")
    result = subprocess.run(
        [
            str(Path(sys.executable).parent / "mkdocs"),
            "build",
            "--strict",
            "--site-dir",
            str(tmp_path / "site"),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
        check=False,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    assert (tmp_path / "site" / "api" / "runtime" / "index.html").exists()


def test_every_docs_page_is_in_the_site_nav():
    """A page left out of mkdocs.yml's nav builds but no reader finds it (mkdocs only
    logs it): every docs/**/*.md, a new family's page included, is listed."""
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    listed = set(re.findall(r":\s*([\w./-]+\.md)\s*$", nav, flags=re.MULTILINE))
    pages = {
        p.relative_to(ROOT / "docs").as_posix() for p in (ROOT / "docs").rglob("*.md")
    }
    assert pages - listed == set(), f"add to mkdocs.yml nav: {sorted(pages - listed)}"
