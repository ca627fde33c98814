"""Rendering of a run: figures, maps, the HTML report and the console lines.

Leaves of the output floor: they draw and format what they are given (an analysis
result, its acceptance, its measures) and never read or write a run folder
(:mod:`glassdist.storage` writes what they render).
"""

from .maps import preview, run_figures

__all__ = ["preview", "run_figures"]
