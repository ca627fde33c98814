"""Write each lazily exporting package's ``if TYPE_CHECKING:`` imports from its lazy homes.

A package whose public names load on first use (:func:`glassdist._lazy.lazy_exports`)
shows static tools nothing: they do not run ``__getattr__``. This script imports each
such package, reads the homes it gave ``lazy_exports`` and writes, between two marker
comments in its ``__init__.py``, the same names as plain imports under ``TYPE_CHECKING``,
which IDEs and mypy read and the interpreter skips.

Usage::

    python scripts/lazy_stubs.py           # rewrite the blocks
    python scripts/lazy_stubs.py --check   # exit 1 when a block is missing or stale
"""

from __future__ import annotations

import argparse
import importlib
import subprocess
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"
BEGIN = "# --- typed names for static tools (scripts/lazy_stubs.py writes this block) ---"
END = "# --- end of the typed names ---"


def lazy_packages() -> list[Path]:
    """Every ``__init__.py`` under ``src/glassdist`` that calls ``lazy_exports``."""
    return sorted(p for p in SRC.glob("glassdist/**/__init__.py") if "lazy_exports(" in p.read_text())


def block(homes: dict[str, str]) -> str:
    """The ``TYPE_CHECKING`` imports naming ``homes`` (``{name: ".module"}`` or ``".module:attr"``)."""
    by_module: dict[str, list[str]] = defaultdict(list)
    for name, home in homes.items():
        module, _, attr = home.partition(":")
        by_module[module].append(f"{attr} as {name}" if attr else name)
    lines = [BEGIN, "if TYPE_CHECKING:"]
    lines += [f"    from {module} import {', '.join(sorted(names))}" for module, names in sorted(by_module.items())]
    lines.append(END)
    return "\n".join(lines) + "\n"


def rewritten(path: Path) -> str:
    """``path``'s text with its typed-names block written from the package's lazy homes."""
    rel = path.relative_to(SRC).parent
    package = importlib.import_module(".".join(rel.parts))
    text = path.read_text()
    new = block(package._LAZY_HOMES)
    if BEGIN in text:
        head, _, rest = text.partition(BEGIN)
        _, _, tail = rest.partition(END + "\n")
        return head + new + tail
    # first time: after the module's imports, before the lazy_exports call
    i = text.index("lazy_exports(")
    line_start = text.rfind("\n\n", 0, i) + 2
    text = text[:line_start] + new + "\n" + text[line_start:]
    if "TYPE_CHECKING" not in text.split(BEGIN)[0]:
        for lazy in ("from .._lazy import lazy_exports", "from ._lazy import lazy_exports"):
            text = text.replace(lazy, "from typing import TYPE_CHECKING\n\n" + lazy, 1)
    return text


def isort(text: str) -> str:
    """``text`` with its imports sorted and wrapped as the project's ruff configuration does."""
    with tempfile.TemporaryDirectory() as tmp:
        f = Path(tmp) / "__init__.py"
        f.write_text(text)
        cfg = SRC.parent / "pyproject.toml"
        subprocess.run([sys.executable, "-m", "ruff", "check", "--quiet", "--fix", "--select", "I",
                        "--config", str(cfg), str(f)], check=False)
        return f.read_text()


def main(argv: list[str] | None = None) -> int:
    """Rewrite (or, with ``--check``, check) every lazy package's typed-names block."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="exit 1 when a block is missing or stale")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(SRC))
    stale = []
    for path in lazy_packages():
        new = isort(rewritten(path))
        if new != path.read_text():
            stale.append(path.relative_to(SRC.parent))
            if not args.check:
                path.write_text(new)
    for p in stale:
        print(f"{'stale' if args.check else 'wrote'}: {p}")
    return 1 if args.check and stale else 0


if __name__ == "__main__":
    raise SystemExit(main())
