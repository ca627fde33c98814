"""The paper's three virtual experiments (§3), re-run on the Virtual Pipeline.

* :func:`run_parity` — §3.1, Table 2, Fig. 6: Analyzer vs analytical model on the
  wavy slab (ratios, Procrustes rotation and scale), plus the bandpass ablation.
* :func:`run_pitch` — §3.2, Figs. 7, 8, 10: biconvex lens at three grid pitches,
  Direct vs Comparative, at one physical smoothing scale.
* :func:`run_rotation` — §3.3, Fig. 9: the same slab with the grid axis-aligned
  and rotated about its normal.
* :func:`run_accuracy` — both methods against the exact ray-traced truth on 13
  scenes (docs/accuracy.md).
* :func:`run_transfer` — the Analyzer's measured transfer function, ray-traced ripples
  and a large lens (docs/transfer_function.md).

Each takes the rendering options of :class:`RunOptions` as keywords (``engine``,
``scale``, ``spp``, ``progress``), renders its scenes once and evaluates them
(:func:`run_scenes`), and returns an :class:`ExperimentResult` (numbers, markdown
table, figures); :func:`write_experiment` writes them. ``glassdist experiment NAME --out DIR`` runs
one from the command line.
"""

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

EXPERIMENTS = {"parity": run_parity, "pitch": run_pitch, "rotation": run_rotation, "accuracy": run_accuracy, "transfer": run_transfer}

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
