"""Exceptions raised for bad input.

Every error a user can cause (a missing file, an image without a grid, a
non-positive distance...) is raised as :class:`InputError`, whose message is a
single line saying what is wrong and how to fix it. The command-line tool prints
that line and exits with status 2, without a traceback.
"""

from __future__ import annotations

__all__ = ["GlassdistError", "InputError", "AnalysisError"]


class GlassdistError(Exception):
    """Base class of the errors glassdist raises on purpose."""


class InputError(GlassdistError, ValueError):
    """The input (file, image, parameter) cannot be used; the message says how to fix it."""


class AnalysisError(GlassdistError, RuntimeError):
    """The analysis could not produce a usable result from valid-looking input."""
