"""Paper Figs. 7, 8 and 10 (§3.2): grid-pitch dependence, Direct vs Comparative.

Same as ``glassdist experiment pitch``; writes pitch.json, pitch.md and the figures to
docs/experiments/ unless --out is given::

    python experiments/pitch.py [--out DIR] [--scale S] [--spp N] [--engine exact|cycles]
"""

import sys
from pathlib import Path

from glassdist.cli import main

if __name__ == "__main__":
    args = sys.argv[1:]
    if "--out" not in args:
        args += ["--out", str(Path(__file__).resolve().parents[1] / "docs" / "experiments")]
    sys.exit(main(["experiment", "pitch", *args]))
