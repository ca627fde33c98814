"""Acceptance of one analysis against a specification (no file I/O, no drawing).

* :mod:`~glassdist.acceptance.spec`: the specification schema, its loaded form, protocol
  resolution and capture checks, verdicts;
* :mod:`~glassdist.acceptance.stats`: statistics over the trusted pixels;
* :mod:`~glassdist.acceptance.zones`: the pane's millimetre frame and its zones;
* :mod:`~glassdist.acceptance.regions`: the worst regions;
* :mod:`~glassdist.acceptance.assess`: :func:`assess`, all of them for one result.
"""

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

# --- typed names for static tools (scripts/lazy_stubs.py writes this block) ---
if TYPE_CHECKING:
    from .assess import METADATA_KEYS, Acceptance, assess
    from .spec import Spec, load_spec
# --- end of the typed names ---

# loaded on first use: reading a specification needs neither the statistics nor scipy.ndimage
__getattr__, __dir__ = lazy_exports(__name__, {
    "METADATA_KEYS": ".assess", "Acceptance": ".assess", "assess": ".assess", "Spec": ".spec", "load_spec": ".spec",
})

__all__ = ["METADATA_KEYS", "Acceptance", "Spec", "assess", "load_spec"]
