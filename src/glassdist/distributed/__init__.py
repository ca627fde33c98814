"""Running glassdist's independent jobs on a Dask cluster (optional extra ``glassdist[distributed]``).

A batch's panes, a sweep's scene variants and an experiment's scenes are
independent jobs. :func:`open_executor` gives an :class:`Executor` that runs them
in this process, one after the other (the default), or on the workers of a Dask
``distributed`` cluster: a local one (``workers=N``) or a running scheduler
(``scheduler="tcp://host:8786"``). Inputs and outputs travel by path, so every
worker must see them under the same path (a shared filesystem);
:meth:`Executor.check_paths` verifies that on each worker before any job runs.

Dask is imported only when a cluster is asked for. See ``docs/user-guide/batches-and-dask.md``.
"""

from ._executor import (
    DaskExecutor,
    Executor,
    JobOutcome,
    SerialExecutor,
    add_scheduler_options,
    open_executor,
)

__all__ = [
    "Executor",
    "SerialExecutor",
    "DaskExecutor",
    "JobOutcome",
    "open_executor",
    "add_scheduler_options",
]
