"""Jobs of many ``glassdist analyze`` runs: child processes, job folders, batches and their index.

* :mod:`~glassdist.jobs.runner`: a child ``glassdist`` process and the job folders it
  writes into (shared by ``glassdist batch``, ``glassdist sweep`` and the web app);
* :mod:`~glassdist.jobs.batch`: manifest, resumable execution, the index
  (:mod:`~glassdist.jobs.index_figures`: its thumbnails and trend plot).
"""

from .batch import EXIT_PANE_ERRORS, Pane, read_manifest, run_batch
from .runner import PaneOutcome, run_glassdist

__all__ = ["EXIT_PANE_ERRORS", "Pane", "PaneOutcome", "read_manifest", "run_batch", "run_glassdist"]
