"""What the sub-command registrations share: scene commands, their options and a terminal progress bar.

Private to the package: the ``_cli`` modules of the subpackages import it; nothing else should.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from pathlib import Path

from .validation import SIGMA_MM, number_option

__all__ = ["folder_option", "progress_reporter", "apply_render_overrides", "add_render_options", "add_scene_command",
           "add_analysis_options"]


def folder_option(text: str) -> Path:
    """argparse type of ``--out``: a folder path; an empty one (which would mean the current folder) is refused."""
    if not text.strip():
        raise argparse.ArgumentTypeError("is empty; give a folder path (new or existing), e.g. --out out/run1")
    return Path(text)


@contextlib.contextmanager
def progress_reporter(enabled: bool = True):
    """Yield ``report(stage, done, total)`` drawing a progress bar on a terminal (no-op otherwise)."""
    if not enabled or not sys.stderr.isatty():
        yield None
        return
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    tasks: dict = {}
    with Progress(TextColumn("{task.description}"), BarColumn(), TimeRemainingColumn(), transient=True) as bar:

        def report(stage: str, done: int, total: int) -> None:
            if stage not in tasks:
                tasks[stage] = bar.add_task(stage, total=total)
            bar.update(tasks[stage], completed=done)

        yield report


def apply_render_overrides(scene, args):
    """Scene with ``--spp`` / ``--seed`` applied."""
    changes = {}
    if getattr(args, "spp", None) is not None:
        changes["samples_per_pixel"] = args.spp
    if getattr(args, "seed", None) is not None:
        changes["seed"] = args.seed
    return scene.with_changes(render=changes) if changes else scene


def add_render_options(p) -> None:
    """Options shared by render and validate."""
    p.add_argument("--engine", default="exact", help="render engine: exact (default) or cycles")
    p.add_argument("--spp", "--samples", dest="spp", type=int,
                   help="samples per pixel (default: the scene's render.samples_per_pixel)")
    p.add_argument("--seed", type=int, help="random seed (default: the scene's render.seed)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def add_scene_command(subparsers, name: str, run, *, help: str, description: str):
    """Add a sub-command that reads a scene file and writes into ``--out DIR``; returns its parser."""
    p = subparsers.add_parser(name, help=help, description=description)
    p.add_argument("scene", type=Path, help="scene file (YAML or JSON)")
    p.add_argument("--out", type=folder_option, required=True, metavar="DIR", help="output folder")
    p.set_defaults(func=run)
    return p


def add_analysis_options(p) -> None:
    """Options shared by predict and validate: analyzer parameters over the scene's ``analysis`` block."""
    p.add_argument("--params", type=Path, metavar="PARAMS.json", help="analyzer parameters overriding the scene's 'analysis'")
    p.add_argument("--sigma-mm", type=number_option(SIGMA_MM), help="reporting smoothing scale on the backdrop, mm")
    p.add_argument("--detrend-degree", type=int, help="total degree of the polynomial detrend")
