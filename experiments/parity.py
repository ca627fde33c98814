"""Paper Table 2 and Fig. 6 (§3.1), with the isotropic-bandpass ablation.

Same as ``glassdist experiment parity``; writes parity.json, parity.md and the figures to
docs/experiments/ unless --out is given::

    python experiments/parity.py [--out DIR] [--scale S] [--spp N] [--engine exact|cycles]
"""

import sys
from pathlib import Path

from glassdist.cli import main

if __name__ == "__main__":
    args = sys.argv[1:]
    if "--out" not in args:
        args += ["--out", str(Path(__file__).resolve().parents[1] / "docs" / "experiments")]
    sys.exit(main(["experiment", "parity", *args]))
