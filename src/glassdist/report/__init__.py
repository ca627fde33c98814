"""Rendering of a run: figures, maps, the HTML report and the console lines.

Leaves of the output floor: they draw and format what they are given (an analysis
result, its acceptance, its measures) and never read or write a run folder
(:mod:`glassdist.storage` writes what they render).
"""

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

# --- typed names for static tools (scripts/lazy_stubs.py writes this block) ---
if TYPE_CHECKING:
    from .maps import run_figures
# --- end of the typed names ---

# loaded on first use: the console lines and the input checks need no plotting stack
__getattr__, __dir__ = lazy_exports(__name__, {"run_figures": ".maps"})

__all__ = ["run_figures"]
