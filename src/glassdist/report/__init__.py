"""A4 visual metrics and the industrial workflow built on them.

The output stage of a run (:mod:`~glassdist.report.outputs`) writes every file of
``glassdist analyze``, for the command line, ``glassdist batch`` and the Python API alike;
beside it: figures, statistics, specifications, acceptance zones and regions, the HTML
report, exports and batches (one module each).
"""

from .outputs import (
    EXIT_SPEC_FAIL,
    OutputFolder,
    StoredResult,
    load_result,
    open_output_folder,
    plan_outputs,
    preview,
    write_outputs,
)

__all__ = [
    "EXIT_SPEC_FAIL",
    "OutputFolder",
    "StoredResult",
    "load_result",
    "open_output_folder",
    "plan_outputs",
    "preview",
    "write_outputs",
]
