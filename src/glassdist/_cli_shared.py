"""What the sub-command registrations share: the render options and a terminal progress bar.

Private to the package: the ``_cli`` modules of the subpackages import it; nothing else should.
"""

from __future__ import annotations

import contextlib
import sys

__all__ = ["progress_reporter", "apply_render_overrides", "add_render_options"]


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
    p.add_argument("--spp", "--samples", dest="spp", type=int, help="samples per pixel (default: the scene's render.samples_per_pixel)")
    p.add_argument("--seed", type=int, help="random seed (default: the scene's render.seed)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
