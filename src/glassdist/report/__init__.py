"""A4 visual metrics and the industrial workflow built on them.

* :mod:`~glassdist.report.figures`: heatmaps, threshold masks, histograms (plots return ``(fig, ax)``).
"""

from .figures import save_channel_heatmaps

__all__ = ["save_channel_heatmaps"]
