"""``glassdist render``: render a scene's distorted and glass-less images (16-bit PNG)."""

from __future__ import annotations

import hashlib
import json
import logging
import time
from pathlib import Path

import numpy as np

from .._cli_shared import add_render_options, add_scene_command, apply_render_overrides, progress_reporter
from .._version import __version__
from ..errors import InputError
from ..io import prepare_output_dir, write_png16
from ..scene import load_scene
from ..validation import safe_text

log = logging.getLogger(__name__)

__all__ = ["register", "run"]


def register(subparsers):
    """Add the ``render`` sub-command."""
    p = add_scene_command(
        subparsers, "render", run,
        help="render a scene: distorted.png and reference.png (16-bit)",
        description="Render the scene's camera view through the glass (distorted.png) and without it "
        "(reference.png), 16-bit linear PNG; --displacement also writes the exact per-pixel landing "
        "displacement (displacement_mm.npy, H x W x 2, backdrop mm).",
    )
    add_render_options(p)
    p.add_argument("--no-reference", action="store_true", help="skip the glass-less reference image")
    p.add_argument("--displacement", action="store_true", help="also write the exact displacement field")
    p.add_argument("--save-blend", type=Path, metavar="FILE", help="with --engine cycles: also save the Blender scene")
    return p


def _check_save_blend(path, scene_path, out_dir) -> None:
    """Refuse a ``--save-blend`` path that would overwrite a file glassdist did not write there itself.

    A file may be replaced only if ``OUT/render.json`` of an earlier render records it
    (same resolved path, same SHA-256) as that render's saved Blender scene.
    """
    p = Path(path)
    shown = safe_text(p)
    if p.suffix.lower() != ".blend":
        raise InputError(f"--save-blend '{shown}' must name a .blend file")
    if not (p.exists() or p.is_symlink()):
        return
    if p.resolve() == Path(scene_path).resolve():
        raise InputError(f"--save-blend '{shown}' is the scene file being rendered; give a new .blend path")
    if p.is_file() and not p.is_symlink():
        try:
            earlier = json.loads((Path(out_dir) / "render.json").read_text(encoding="utf-8")).get("save_blend") or {}
        except (OSError, ValueError, AttributeError):
            earlier = {}
        if (isinstance(earlier, dict) and earlier.get("path") == str(p.resolve())
                and earlier.get("sha256") == hashlib.sha256(p.read_bytes()).hexdigest()):
            return  # this folder's own earlier output
    raise InputError(f"--save-blend '{shown}' already exists and was not written by an earlier render into "
                     f"'{safe_text(out_dir)}'; give a new .blend path (glassdist never overwrites other files)")


def run(args) -> int:
    from . import get_renderer, landing_points, render_scene

    scene = apply_render_overrides(load_scene(args.scene), args)
    if args.save_blend is not None:
        _check_save_blend(args.save_blend, args.scene, args.out)
    engine = get_renderer(args.engine)
    if args.save_blend is not None:
        if not hasattr(engine, "save_blend"):
            raise InputError("--save-blend needs --engine cycles")
        engine.save_blend = args.save_blend
    out = prepare_output_dir(args.out)
    timings = {}
    with progress_reporter(not args.no_progress) as report:
        jobs = [("distorted", False)] + ([] if args.no_reference else [("reference", True)])
        for name, ref in jobs:
            t0 = time.perf_counter()
            cb = None if report is None else (lambda d, t, n=name: report(f"render {n}", d, t))
            img = render_scene(scene, engine=engine, reference=ref, progress=cb)
            timings[f"{name}_s"] = time.perf_counter() - t0
            write_png16(out / f"{name}.png", img)
    if args.displacement:
        lp = landing_points(scene)
        np.save(out / "displacement_mm.npy", lp.displacement_mm.astype(np.float32))
    record = {
        "glassdist_version": __version__,
        "scene": scene.model_dump(mode="json"),
        "engine": engine.name,
        "timings": timings,
    }
    if args.save_blend is not None and Path(args.save_blend).is_file():
        blend = Path(args.save_blend).resolve()
        record["save_blend"] = {"path": str(blend), "sha256": hashlib.sha256(blend.read_bytes()).hexdigest()}
    (out / "render.json").write_text(json.dumps(record, indent=2), encoding="utf-8")
    h, w = scene.camera.shape
    print(f"rendered {w}x{h} px at {scene.render.samples_per_pixel} spp with engine '{engine.name}' "
          f"in {sum(timings.values()):.1f} s; written to {out}")
    return 0
