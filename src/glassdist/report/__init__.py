"""Rendering of a run: figures, maps, the HTML report and the console lines.

Leaves of the output floor: they draw and format what they are given (an analysis
result, its acceptance, its measures) and never read or write a run folder
(:mod:`glassdist.storage` writes what they render).
"""

from .._lazy import lazy_exports

# loaded on first use: the console lines and the input checks need no plotting stack
__getattr__, __dir__ = lazy_exports(__name__, {"run_figures": ".maps"})

__all__ = ["run_figures"]
