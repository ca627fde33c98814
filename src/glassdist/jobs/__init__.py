"""Jobs of many ``glassdist analyze`` runs: child processes, job folders, batches and their index.

* :mod:`~glassdist.jobs.request`: the typed run request a child process is sent
  (``analyze`` or ``validate``, serialised as JSON);
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
    from .request import AnalyzeRequest, ValidateRequest
    from .runner import PaneOutcome, run_glassdist, run_request
# --- end of the typed names ---

# loaded on first use: `glassdist --help` and the other commands register `batch` without them
__getattr__, __dir__ = lazy_exports(__name__, {
    "EXIT_PANE_ERRORS": ".batch", "Pane": ".batch", "read_manifest": ".batch", "run_batch": ".batch",
    "PaneOutcome": ".runner", "run_glassdist": ".runner", "run_request": ".runner",
    "AnalyzeRequest": ".request", "ValidateRequest": ".request",
})

__all__ = ["EXIT_PANE_ERRORS", "AnalyzeRequest", "Pane", "PaneOutcome", "ValidateRequest", "read_manifest", "run_batch",
           "run_glassdist", "run_request"]
