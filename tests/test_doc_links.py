"""Every relative link of the README and the docs reaches a file of the repository, and an anchor a heading."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")),
         ROOT / "valve_gym" / "agents" / "policies" / "README.md"]
LINK = re.compile(r"\]\(([^)\s]+)\)")


def slug(heading: str) -> str:
    """GitHub's anchor of a Markdown heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def anchors(page: Path) -> set[str]:
    """The anchors of a page's headings (outside code blocks)."""
    out, code = set(), False
    for line in page.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            code = not code
        elif not code and line.startswith("#"):
            out.add(slug(line.lstrip("#")))
    return out


def links(page: Path) -> list[str]:
    return [m for m in LINK.findall(page.read_text(encoding="utf-8")) if not re.match(r"[a-z]+:", m)]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_reach_a_file_and_a_heading(page):
    bad = []
    for link in links(page):
        path, _, anchor = link.partition("#")
        target = (page.parent / path).resolve() if path else page
        if not target.exists():
            bad.append(f"{link}: no file {target.relative_to(ROOT) if ROOT in target.parents else target}")
        elif anchor and target.suffix == ".md" and anchor not in anchors(target):
            bad.append(f"{link}: no heading with anchor #{anchor} in {target.name}")
    assert not bad, "\n".join(bad)


def test_slug_is_githubs():
    assert slug(" Effect naming on another simulator") == "effect-naming-on-another-simulator"
    assert slug(" Proof 2 — concealed-effect suites") == "proof-2--concealed-effect-suites"
    assert slug(" Fleet mode (`valve_gym/fleet/`)") == "fleet-mode-valve_gymfleet"


def test_changelog_has_no_relative_links():
    """CHANGELOG.md is read on GitHub from the root and included in the docs site (docs/changelog.md), where a
    relative link means another folder: it names pages in backticks instead."""
    assert links(ROOT / "CHANGELOG.md") == []
