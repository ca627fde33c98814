"""Render the project's example photos with its exact tracer, and check them.

Every example photo in the tree is rendered here from a scene file of ``examples/scenes/``
by ``glassdist render`` (exact tracer, the scene's own samples per pixel and seed), so that
the examples are the project's own and can be made again (bit-identical on the machine that
rendered them; another floating-point library may differ by a count in the last bit)::

    .venv/bin/python scripts/render_examples.py             # render every example (about 1.5 min on 2 cores)
    .venv/bin/python scripts/render_examples.py --check     # render into a temporary folder, compare, change nothing
    .venv/bin/python scripts/render_examples.py reflection  # one of them (the names of EXAMPLES)
    .venv/bin/python scripts/render_examples.py --figure    # and the README's figure

``examples/images/SHA256SUMS`` lists the SHA-256 of every photo as rendered;
``tests/test_examples.py`` checks the files against it and re-renders the small reflection
pair.

The figure of the README (``docs/_static/quickstart_phi_eff.png``) is the ``phi_eff.png``
that the README's Quick start writes; ``--figure`` makes it again.
"""

from __future__ import annotations

import argparse
import hashlib
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SCENES = REPO / "examples" / "scenes"
SUMS = REPO / "examples" / "images" / "SHA256SUMS"
FIGURE = REPO / "docs" / "_static" / "quickstart_phi_eff.png"

#: name: (scene file, {rendered file: path in the tree}); the reference is rendered only where it is kept.
EXAMPLES: dict[str, tuple[str, dict[str, str]]] = {
    "factory": ("factory_pane.yaml", {"distorted.png": "examples/images/factory_pane.png",
                                      "reference.png": "examples/images/factory_reference.png"}),
    "factory_clean": ("factory_pane_clean.yaml", {"distorted.png": "examples/images/factory_pane_clean.png"}),
    "site": ("site_pane.yaml", {"distorted.png": "examples/images/site_pane.png"}),
    "reflection": ("roller_wave_reflection.yaml", {"distorted.png": "examples/reflection/pane.png",
                                                   "reference.png": "examples/reflection/flat.png"}),
}

#: The README's Quick start analysis (its figure is this run's phi_eff.png).
QUICK_START = ["analyze", "examples/images/factory_pane.png", "--reference", "examples/images/factory_reference.png",
               "--pattern", "checkerboard", "--pitch-mm", "10", "--distance-m", "1"]


def _glassdist(*args: str) -> None:
    env_src = str(REPO / "src")
    code = f"import sys; sys.path.insert(0, {env_src!r}); from glassdist.cli import main; sys.exit(main(sys.argv[1:]))"
    cmd = [sys.executable, "-c", code, *args]
    subprocess.run(cmd, check=True, cwd=REPO)


def render(name: str, folder: Path) -> dict[str, Path]:
    """Render example ``name`` into ``folder``; ``{path in the tree: rendered file}``."""
    scene, files = EXAMPLES[name]
    args = ["render", str(SCENES / scene), "--out", str(folder), "--no-progress"]
    if "reference.png" not in files:
        args.append("--no-reference")
    _glassdist(*args)
    return {target: folder / rendered for rendered, target in files.items()}


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def read_sums() -> dict[str, str]:
    """``{path in the tree: SHA-256}`` from ``examples/images/SHA256SUMS``."""
    sums = {}
    for line in SUMS.read_text(encoding="utf-8").splitlines():
        if line.strip():
            digest, path = line.split(maxsplit=1)
            sums[path] = digest
    return sums


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", metavar="NAME", help=f"examples to render: {', '.join(EXAMPLES)} (default: all)")
    ap.add_argument("--check", action="store_true", help="render into a temporary folder and compare, write nothing")
    ap.add_argument("--figure", action="store_true", help="also make the README's figure from the Quick start")
    args = ap.parse_args(argv)
    names = args.names or list(EXAMPLES)
    unknown = sorted(set(names) - set(EXAMPLES))
    if unknown:
        ap.error(f"unknown example {', '.join(unknown)}; choose from {', '.join(EXAMPLES)}")
    sums = read_sums() if SUMS.exists() else {}
    differ = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            for target, rendered in render(name, Path(tmp) / name).items():
                digest = sha256(rendered)
                if args.check:
                    if sums.get(target) != digest:
                        differ.append(target)
                    continue
                shutil.copyfile(rendered, REPO / target)
                sums[target] = digest
        if args.figure and not args.check:
            _glassdist(*QUICK_START, "--out", str(Path(tmp) / "quick"), "--no-history", "-q")
            FIGURE.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(Path(tmp) / "quick" / "phi_eff.png", FIGURE)
    if args.check:
        print("\n".join(f"differs: {t}" for t in differ) or "every rendered example matches SHA256SUMS")
        return 1 if differ else 0
    SUMS.write_text("".join(f"{d}  {p}\n" for p, d in sorted(sums.items())), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
