"""Paper Fig. 9 (§3.3): in-plane grid rotation.

Same as ``glassdist experiment rotation``; writes rotation.json, rotation.md and the figures to
docs/experiments/ unless --out is given::

    python experiments/rotation.py [--out DIR] [--scale S] [--spp N] [--engine exact|cycles]
"""

import sys
from pathlib import Path

from glassdist.cli import main

if __name__ == "__main__":
    args = sys.argv[1:]
    if "--out" not in args:
        args += ["--out", str(Path(__file__).resolve().parents[1] / "docs" / "experiments")]
    sys.exit(main(["experiment", "rotation", *args]))
