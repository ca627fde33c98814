"""Where the benchmarks read the real photographs: the shared data folder beside the repository.

The photos (a checkerboard seen through disturbed water: ``reference.png``,
``distorted_waves.bmp``, ``distorted_floating_ring.bmp``) come from another repository, so they
are never in this tree; CI has them at ``../shared/data/real-checkerboard-water/``.
"""

from __future__ import annotations

from pathlib import Path

#: The real photographs' folder, beside the repository.
REAL_PHOTOS = Path(__file__).resolve().parents[2] / "shared" / "data" / "real-checkerboard-water"


def real_photos() -> Path:
    """:data:`REAL_PHOTOS`; where it is absent, exits (status 1, nothing measured) saying so."""
    if not (REAL_PHOTOS / "reference.png").is_file():
        raise SystemExit(f"skipped: needs the real photographs in {REAL_PHOTOS} (the shared data folder beside "
                         "the repository), which is absent here")
    return REAL_PHOTOS
