"""Every relative link of the repository's Markdown (README, docs, examples) leads to a file that exists.

A link is ``[text](target)``, ``![alt](target)`` or a reference definition ``[name]: target``
outside fenced blocks and inline code; web addresses (``scheme:``) and links to an anchor of
the same page (``#...``) are not files and are left out. The anchor of ``file.md#anchor`` is
not checked here (the strict site build checks the anchors of the pages it builds).
"""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _markdown_files() -> list[Path]:
    spec = importlib.util.spec_from_file_location("update_quoted_outputs", REPO / "scripts" / "update_quoted_outputs.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(spec.name, module)
    spec.loader.exec_module(module)
    return module.markdown_files(REPO)


_INLINE = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^()\s>]+(?:\([^()\s]*\)[^()\s>]*)*)>?(?:\s+\"[^\"]*\")?\s*\)")
_DEFINITION = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s+.*)?$")
_SCHEME = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.-]*:")


def prose(text: str) -> str:
    """``text`` less its fenced blocks and inline code (lines kept, so that line numbers hold)."""
    out, fence = [], None
    for line in text.splitlines():
        marker = re.match(r"^\s*(`{3,}|~{3,})", line)
        if fence is None and marker:
            fence = marker.group(1)[0] * len(marker.group(1))
            out.append("")
        elif fence is not None:
            if line.strip().startswith(fence):
                fence = None
            out.append("")
        else:
            out.append(re.sub(r"(`+).*?\1", "", line))
    return "\n".join(out)


def relative_links(path: Path) -> list[tuple[int, str]]:
    """``(line, target)`` of every relative link of ``path`` (its anchor left out)."""
    found = []
    for number, line in enumerate(prose(path.read_text(encoding="utf-8")).splitlines(), 1):
        targets = [m.group(1) for m in _INLINE.finditer(line)]
        if (d := _DEFINITION.match(line)) is not None:
            targets.append(d.group(1))
        for target in targets:
            if _SCHEME.match(target) or target.startswith("#"):
                continue
            found.append((number, target.split("#", 1)[0]))
    return found


def broken_links(path: Path) -> list[str]:
    return [f"{path.relative_to(REPO)}:{number}: {target}" for number, target in relative_links(path)
            if not (path.parent / target).exists()]


DOC_FILES = _markdown_files()


def test_markdown_files_found():
    names = {str(p.relative_to(REPO)) for p in DOC_FILES}
    assert "README.md" in names and "docs/index.md" in names and "examples/factory/README.md" in names


def test_link_extraction_can_fail(tmp_path):
    """A missing file is broken; a present one, a web address, an anchor and a link in code are not."""
    (tmp_path / "there.md").write_text("x\n")
    page = tmp_path / "page.md"
    page.write_text("[a](there.md) [b](missing.md#x) ![c](<there.md>) [d](https://example.org/x.md)\n"
                    "[e](#anchor) `[f](gone.md)`\n```\n[g](gone.md)\n```\n[h]: also_missing.md\n")
    assert [t for _, t in relative_links(page)] == ["there.md", "missing.md", "there.md", "also_missing.md"]
    assert [t for _, t in relative_links(page) if not (tmp_path / t).exists()] == ["missing.md", "also_missing.md"]


@pytest.mark.parametrize("path", DOC_FILES, ids=[str(p.relative_to(REPO)) for p in DOC_FILES])
def test_relative_links_resolve(path):
    assert broken_links(path) == []


def test_every_public_module_has_a_reference_page():
    """A module added to the package gets its page in docs/reference/modules (and so in the built API reference)."""
    src = REPO / "src" / "glassdist"
    pages = {p.stem for p in (REPO / "docs" / "reference" / "modules").glob("glassdist*.md")}
    modules = set()
    for path in src.rglob("*.py"):
        parts = list(path.relative_to(src.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        if len(parts) > 1 and not any(p.startswith("_") for p in parts) and "migrations" not in parts:
            modules.add(".".join(parts))
    assert sorted(modules - pages) == []
