"""Jobs of many ``glassdist analyze`` runs: child processes, job folders, batches and their index.

* :mod:`~glassdist.jobs.runner`: a child ``glassdist`` process and the job folders it
  writes into (shared by ``glassdist batch``, ``glassdist sweep`` and the web app);
* :mod:`~glassdist.jobs.batch`: manifest, resumable execution, the index
  (:mod:`~glassdist.jobs.index_figures`: its thumbnails and trend plot).
"""

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

# --- typed names for static tools (scripts/lazy_stubs.py writes this block) ---
if TYPE_CHECKING:
    from .batch import EXIT_PANE_ERRORS, Pane, read_manifest, run_batch
    from .runner import PaneOutcome, run_glassdist
# --- end of the typed names ---

# loaded on first use: `glassdist --help` and the other commands register `batch` without them
__getattr__, __dir__ = lazy_exports(__name__, {
    "EXIT_PANE_ERRORS": ".batch", "Pane": ".batch", "read_manifest": ".batch", "run_batch": ".batch",
    "PaneOutcome": ".runner", "run_glassdist": ".runner",
})

__all__ = ["EXIT_PANE_ERRORS", "Pane", "PaneOutcome", "read_manifest", "run_batch", "run_glassdist"]
