"""The README stays a short start, user docs name no internal issue numbers, and every relative
link in README.md and docs/ leads to a file that exists. (`make docs` checks the rest: pages,
anchors and the API reference, with warnings as errors.)"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
PAGES = sorted((ROOT / "docs").rglob("*.md"))
MARKDOWN = [README, *PAGES]
README_MAX_LINES = 150

FENCE = re.compile(r"^(```|~~~).*?^\1", re.S | re.M)
CODE_SPAN = re.compile(r"`[^`\n]*`")
LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
HTML_LINK = re.compile(r"""<(?:img|a)\b[^>]*?\b(?:src|href)\s*=\s*["']([^"']+)["']""", re.I)
ISSUE = re.compile(r"\bissues?\s*#?\d+", re.I)


def _prose(path: Path) -> str:
    """The file's text without code blocks and code spans (commands, not links)."""
    return CODE_SPAN.sub("", FENCE.sub("", path.read_text(encoding="utf-8")))


def _relative_links(path: Path) -> list[str]:
    text = _prose(path)
    targets = LINK.findall(text) + HTML_LINK.findall(text)
    return [t for t in targets if not re.match(r"^([a-z][a-z0-9+.-]*:|#|//)", t, re.I)]


def test_the_pages_are_found():
    assert README.is_file()
    assert {p.name for p in PAGES} >= {"index.md", "getting-started.md", "cli.md"}


def test_the_readme_is_short():
    lines = README.read_text(encoding="utf-8").count("\n")
    assert lines <= README_MAX_LINES, (
        f"README.md has {lines} lines (at most {README_MAX_LINES}): move details to docs/"
    )


@pytest.mark.parametrize("path", MARKDOWN, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_internal_issue_numbers(path):
    found = [
        f"line {n}: {line.strip()}"
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if ISSUE.search(line)
    ]
    assert not found, f"{path.name} cites internal issues (say what, not which ticket): {found}"


@pytest.mark.parametrize("path", MARKDOWN, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_leads_to_a_file(path):
    missing = []
    for target in _relative_links(path):
        file = target.split("#", 1)[0].split("?", 1)[0]
        if file and not (path.parent / file).exists():
            missing.append(target)
    assert not missing, f"{path.relative_to(ROOT)} links to files that do not exist: {missing}"


def test_the_link_finder_finds_links(tmp_path):
    page = tmp_path / "page.md"
    page.write_text(
        "[a](a.md) ![b](img/b.png){ width=50% } [c](https://x.org) [d](#here) "
        '<img src="e.png" width="49%"> `[f](not-a-link.md)`\n'
        "```bash\n[g](nor-this.md)\n```\n[h](sub/h.md#anchor)\n",
        encoding="utf-8",
    )
    assert _relative_links(page) == ["a.md", "img/b.png", "sub/h.md#anchor", "e.png"]
    assert ISSUE.search("fixed in issue 15") and ISSUE.search("Issues #3")
    assert not ISSUE.search("mujocolab/mjlab#519") and not ISSUE.search("an issue of size")
