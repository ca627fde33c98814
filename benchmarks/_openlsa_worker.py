"""Runs OpenLSA (Localized Spectrum Analysis) on the benchmark images, inside OpenLSA's own environment.

OpenLSA pins numpy < 2, so it runs in a separate interpreter (benchmarks/setup_openlsa.sh).
Prints one JSON line: the time, peak RSS, and the path of the displacement (H, W, 2; x, y) in
glassdist's convention (delta = -u, u being OpenLSA's reference-to-current displacement).
"""

import json
import resource
import sys
import time
from pathlib import Path

import numpy as np


def main():
    task = json.loads(sys.argv[sys.argv.index("--worker") + 1])
    folder = Path(task["folder"])
    # OpenLSA's pattern matching expects an 8-bit-like intensity scale.
    ref = np.load(folder / "ref.npy").astype(np.float64) * 255.0
    img = np.load(folder / "img.npy").astype(np.float64) * 255.0
    from openlsa import OpenLSA

    t0 = time.perf_counter()
    lsa = OpenLSA(ref, verbose=False, display=False)
    kernel = lsa.compute_kernel(std=lsa.pitch().max())
    phi_0, _ = lsa.compute_phases_mod(ref, kernel)
    phi_t, _ = lsa.compute_phases_mod(img, kernel)
    phi_t, _ = lsa.temporal_unwrap(ref, img, phi_0, phi_t)
    u = lsa.compute_displacement(phi_0, phi_t, min_iter=6)
    seconds = time.perf_counter() - t0
    # OpenLSA positions are z = col + 1j*row (its map_coordinates call reads (z.imag, z.real)).
    disp = np.stack([-u.real, -u.imag], axis=-1)
    out = folder / "openlsa_disp.npy"
    np.save(out, disp)
    print(json.dumps({"kind": "openlsa", "seconds": seconds,
                      "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
                      "displacement": str(out)}))


if __name__ == "__main__":
    main()
