"""A run on disk: its folder, its files and its summary.

* :mod:`~glassdist.storage.folder`: the run folder, planned and taken before the analysis
  (checks, lock, leftovers of a killed run, an earlier run's files);
* :mod:`~glassdist.storage.fields`: ``result.npz`` in both layouts (written and read back
  by :func:`load_result`), ``statistics.csv`` and the exports;
* :mod:`~glassdist.storage.writer`: every file of ``glassdist analyze``, for the command
  line, ``glassdist batch`` and the Python API alike (:func:`write_outputs`).
"""

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

# --- typed names for static tools (scripts/lazy_stubs.py writes this block) ---
if TYPE_CHECKING:
    from .fields import FIELD_LAYOUTS, GRID_KEYS, SUMMARY_NAME, StoredResult, load_result
    from .folder import OutputFolder, open_output_folder, plan_outputs
    from .writer import EXIT_OK, EXIT_SPEC_FAIL, write_outputs
# --- end of the typed names ---

# loaded on first use: a run's record and folder need neither the figures nor the report
__getattr__, __dir__ = lazy_exports(__name__, {
    **dict.fromkeys(("FIELD_LAYOUTS", "GRID_KEYS", "SUMMARY_NAME", "StoredResult", "load_result"), ".fields"),
    **dict.fromkeys(("OutputFolder", "open_output_folder", "plan_outputs"), ".folder"),
    **dict.fromkeys(("EXIT_OK", "EXIT_SPEC_FAIL", "write_outputs"), ".writer"),
})

__all__ = [
    "EXIT_OK",
    "EXIT_SPEC_FAIL",
    "FIELD_LAYOUTS",
    "GRID_KEYS",
    "SUMMARY_NAME",
    "OutputFolder",
    "StoredResult",
    "load_result",
    "open_output_folder",
    "plan_outputs",
    "write_outputs",
]
