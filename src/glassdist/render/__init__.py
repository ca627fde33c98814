"""Branch 1 of the Virtual Pipeline: rendering a scene (paper §2.1).

A renderer is any object with a ``name`` and a method

``render(scene, *, reference: bool, rng: numpy.random.Generator, progress=None) -> ndarray``

returning a linear grey image (H, W) in [0, 1] of the scene's camera, with the
glass (``reference=False``) or without it (``reference=True``), sampled with
``scene.render.samples_per_pixel`` samples per pixel and with the scene's
imaging effects applied; ``progress(done, total)`` may be called while it runs.
:func:`get_renderer` returns an engine by name: ``"exact"`` (the built-in
vectorised NumPy ray tracer, default) or ``"cycles"`` (optional, loaded on
demand). The exact engine also returns exact landing points per pixel
(:func:`landing_points`), i.e. the ground-truth displacement.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Callable, Protocol, runtime_checkable

import numpy as np

from .._lazy import lazy_exports
from ..errors import InputError
from ..scene import Scene

# --- typed names for static tools (scripts/lazy_stubs.py writes this block) ---
if TYPE_CHECKING:
    from .imaging import apply_imaging
    from .tracer import ExactTracer, Landing, TraceResult, landing_points, refract, render_intensity, trace_rays
# --- end of the typed names ---

# the engine loads on first use: the sub-commands register without scipy.ndimage
__getattr__, __dir__ = lazy_exports(__name__, {
    "apply_imaging": ".imaging",
    **dict.fromkeys(("ExactTracer", "Landing", "TraceResult", "landing_points", "refract", "render_intensity",
                     "trace_rays"), ".tracer"),
})

__all__ = [
    "Renderer",
    "get_renderer",
    "ENGINES",
    "render_scene",
    "ExactTracer",
    "Landing",
    "TraceResult",
    "landing_points",
    "trace_rays",
    "refract",
    "render_intensity",
    "apply_imaging",
]

ENGINES = {
    "exact": ("glassdist.render.tracer", "ExactTracer"),
    "cycles": ("glassdist.render.cycles", "CyclesRenderer"),
}


@runtime_checkable
class Renderer(Protocol):
    """What a render engine provides (see the module docstring)."""

    name: str

    def render(
        self,
        scene: Scene,
        *,
        reference: bool,
        rng: np.random.Generator,
        progress: Callable[[int, int], None] | None = None,
    ) -> np.ndarray:
        """Render ``scene`` (or, with ``reference=True``, its glass-less reference) as a float image in [0, 1]."""
        ...


def get_renderer(name: str = "exact") -> Renderer:
    """Return a render engine by name (``"exact"`` or ``"cycles"``).

    Raises
    ------
    InputError
        Unknown name, or an engine whose optional dependencies are not installed.
    """
    if name not in ENGINES:
        raise InputError(f"unknown render engine '{name}'; choose one of: {', '.join(ENGINES)}")
    module, attr = ENGINES[name]
    try:
        cls = getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError) as exc:
        raise InputError(f"render engine '{name}' is not available ({exc}); use --engine exact") from None
    return cls()


def render_scene(
    scene: Scene,
    *,
    reference: bool = False,
    engine: str | Renderer = "exact",
    seed: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> np.ndarray:
    """Render one image of a scene with a seeded generator.

    The distorted image uses ``default_rng([seed, 0])`` and the reference
    ``default_rng([seed, 1])`` (``seed`` defaults to ``scene.render.seed``), so the
    two never share jitter or noise and every run is reproducible.

    Examples
    --------
    A flat slab turned 30 deg in front of a checkerboard, 64 x 48 px at 4 samples per pixel:

    >>> import numpy as np
    >>> from glassdist.render import render_scene
    >>> from glassdist.scene import scene_from_dict
    >>> scene = scene_from_dict({
    ...     "pane": {"size_mm": [1400, 1000], "thickness_mm": 20, "refractive_index": 1.52, "yaw_deg": 30},
    ...     "backdrop": {"pattern": "checkerboard", "pitch_mm": 100, "distance_m": 10},
    ...     "camera": {"focal_length_mm": 300, "sensor_width_mm": 36, "pixels": [64, 48], "position_mm": [0, 0, -4000]},
    ...     "render": {"samples_per_pixel": 4, "seed": 7}})
    >>> distorted = render_scene(scene)
    >>> reference = render_scene(scene, reference=True)
    >>> distorted.shape, bool(distorted.min() >= 0.0 and distorted.max() <= 1.0)
    ((48, 64), True)
    >>> bool(np.array_equal(distorted, render_scene(scene)))  # seeded: reproducible
    True
    >>> bool(np.abs(distorted - reference).max() > 0.1)  # the slab shifts the pattern
    True
    """
    eng = get_renderer(engine) if isinstance(engine, str) else engine
    seed = scene.render.seed if seed is None else seed
    rng = np.random.default_rng([int(seed), 1 if reference else 0])
    return eng.render(scene, reference=reference, rng=rng, progress=progress)
