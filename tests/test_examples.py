"""The example photos are the project's own: rendered by its tracer, and no file of the shared data in the tree.

``scripts/render_examples.py`` renders every example photo from its scene file and records its
SHA-256 in ``examples/images/SHA256SUMS``; these tests check the files against the record,
render the small reflection pair again and compare it, and hash every file of the tree against
the real photographs of the shared data folder (which come from another repository).
"""

from __future__ import annotations

import hashlib
import importlib.util
import subprocess

import cv2
import numpy as np
import pytest

from conftest import DATA, REPO, needs_real_photos


def _script():
    spec = importlib.util.spec_from_file_location("render_examples", REPO / "scripts" / "render_examples.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _sha256(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_every_example_photo_is_a_recorded_render():
    """Each photo under examples/images and examples/reflection is listed with its SHA-256, and only those."""
    script = _script()
    sums = script.read_sums()
    targets = {t for _, files in script.EXAMPLES.values() for t in files.values()}
    assert set(sums) == targets
    photos = {str(p.relative_to(REPO)) for folder in ("examples/images", "examples/reflection")
              for p in (REPO / folder).iterdir() if p.suffix.lower() in {".png", ".bmp", ".tif", ".tiff", ".jpg"}}
    assert photos == targets
    assert {t: _sha256(REPO / t) for t in targets} == sums
    for t in targets:  # small enough for a quick Quick start: about 1 Mpx or less
        h, w = cv2.imread(str(REPO / t), cv2.IMREAD_UNCHANGED).shape[:2]
        assert h * w <= 1024 * 1024, t


def test_the_readme_figure_is_the_quick_starts():
    """The README's figure is made by the README's Quick start (``render_examples.py --figure``)."""
    script = _script()
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    assert " ".join(["glassdist", *script.QUICK_START]) in readme
    assert str(script.FIGURE.relative_to(REPO)) in readme and script.FIGURE.is_file()


@pytest.mark.slow
def test_the_reflection_pair_renders_again_as_committed(tmp_path):
    """``glassdist render`` of its scene gives the committed pair again (measured: bit-identical, 6 s)."""
    script = _script()
    for target, rendered in script.render("reflection", tmp_path / "reflection").items():
        old = cv2.imread(str(REPO / target), cv2.IMREAD_UNCHANGED).astype(np.int64)
        new = cv2.imread(str(rendered), cv2.IMREAD_UNCHANGED).astype(np.int64)
        assert old.shape == new.shape and old.dtype == new.dtype
        # one count of 65535 allowed for a different floating-point library; measured 0 here
        assert np.abs(old - new).max() <= 1, target


@needs_real_photos
def test_no_file_of_the_tree_is_a_file_of_the_shared_data():
    """No file of the repository (tracked or not, outside .git and virtual environments) equals a shared one."""
    shared = {_sha256(p): p.name for p in DATA.rglob("*") if p.is_file()}
    assert len(shared) >= 3
    listed = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=REPO,
                            capture_output=True, check=True).stdout.decode().split("\0")
    sizes = {p.stat().st_size for p in DATA.rglob("*") if p.is_file()}
    same = [name for name in filter(None, listed)
            if (REPO / name).is_file() and (REPO / name).stat().st_size in sizes
            and _sha256(REPO / name) in shared]
    assert same == []
