"""The paper's three virtual experiments (§3), re-run on the Virtual Pipeline.

* :func:`run_parity` — §3.1, Table 2, Fig. 6: Analyzer vs analytical model on the
  wavy slab (ratios, Procrustes rotation and scale), plus the bandpass ablation.
* :func:`run_pitch` — §3.2, Figs. 7, 8, 10: biconvex lens at three grid pitches,
  Direct vs Comparative, at one physical smoothing scale.
* :func:`run_rotation` — §3.3, Fig. 9: the same slab with the grid axis-aligned
  and rotated about its normal.
* :func:`run_accuracy` — both methods against the exact ray-traced truth on 13
  scenes (docs/validation/accuracy.md).
* :func:`run_transfer` — the Analyzer's measured transfer function, ray-traced ripples
  and a large lens (docs/explanation/transfer-function.md).

Each takes the rendering options of :class:`RunOptions` as keywords (``engine``,
``scale``, ``spp``, ``progress``), renders its scenes once and evaluates them
(:func:`run_scenes`), and returns an :class:`ExperimentResult` (numbers, markdown
table, figures); :func:`write_experiment` writes them. ``glassdist experiment NAME --out DIR`` runs
one from the command line.
"""

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

# --- typed names for static tools (scripts/lazy_stubs.py writes this block) ---
if TYPE_CHECKING:
    from ._common import (
        ExperimentResult,
        Inputs,
        RunOptions,
        SceneRun,
        evaluate,
        render_inputs,
        run_scenes,
        scaled_scene,
        write_experiment,
    )
    from .accuracy import run_accuracy
    from .parity import run_parity
    from .pitch import run_pitch
    from .rotation import run_rotation
    from .transfer import run_transfer
# --- end of the typed names ---

_HOMES = {name: "._common" for name in ("ExperimentResult", "Inputs", "RunOptions", "SceneRun", "evaluate",
                                         "render_inputs", "run_scenes", "scaled_scene", "write_experiment")}
_HOMES.update(run_accuracy=".accuracy", run_parity=".parity", run_pitch=".pitch", run_rotation=".rotation",
              run_transfer=".transfer")
# loaded on first use: `glassdist --help` and the other commands register `experiment` without them
_lazy_getattr, _lazy_dir = lazy_exports(__name__, _HOMES)


#: the experiments' names, in the order of ``glassdist experiment --help``
_NAMES = ("parity", "pitch", "rotation", "accuracy", "transfer")


def __getattr__(name):
    if name == "EXPERIMENTS":  # name -> run function
        globals()[name] = {n: _lazy_getattr(f"run_{n}") for n in _NAMES}
        return globals()[name]
    return _lazy_getattr(name)


def __dir__():
    return sorted({*_lazy_dir(), "EXPERIMENTS"})


__all__ = [
    "EXPERIMENTS",
    "ExperimentResult",
    "Inputs",
    "RunOptions",
    "SceneRun",
    "evaluate",
    "render_inputs",
    "run_scenes",
    "scaled_scene",
    "write_experiment",
    "run_parity",
    "run_pitch",
    "run_rotation",
    "run_transfer",
    "run_accuracy",
]
