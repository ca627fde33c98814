"""Validation figure (paper Fig. 6): captures, then Analyzer vs analytical phi_eff and phi_shear."""

from __future__ import annotations

import numpy as np

__all__ = ["validation_figure"]


def validation_figure(validation, distorted: np.ndarray, reference: np.ndarray, *, fig=None):
    """Draw the 3 x 2 comparison panel.

    Top row: reference and distorted captures with the compared region outlined
    in red. Middle row: phi_eff from the Analyzer (left) and the analytical model
    (right). Bottom row: the same for phi_shear. Each row shares its colour
    limits; titles give the mean |phi| over the compared region.

    Returns
    -------
    fig, axes : matplotlib Figure and (3, 2) array of Axes
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    if fig is None:
        fig = plt.figure(figsize=(10, 11))
    axes = fig.subplots(3, 2)
    sel = validation.valid
    for ax, img, title in ((axes[0, 0], reference, "reference (no glass)"), (axes[0, 1], distorted, "distorted")):
        ax.imshow(img, cmap="gray", vmin=0, vmax=1, interpolation="nearest")
        ax.contour(sel.astype(float), levels=[0.5], colors="red", linewidths=1.0)
        ax.set_title(title)
    for row, (name, label, cmap) in enumerate(
        (("phi_eff_mD", r"$\phi_{eff}$", "RdBu_r"), ("phi_shear_mD", r"$\phi_{shear}$", "viridis")), start=1
    ):
        maps = [np.where(sel, getattr(src, name), np.nan) for src in (validation.analysis, validation.analytical)]
        lim = max(float(np.nanpercentile(np.abs(m), 99.5)) for m in maps) or 1.0
        vmin = -lim if cmap == "RdBu_r" else 0.0
        for col, (m, who) in enumerate(zip(maps, ("Analyzer", "analytical model"))):
            ax = axes[row, col]
            im = ax.imshow(m, cmap=cmap, vmin=vmin, vmax=lim, interpolation="nearest")
            ax.set_title(f"{who} {label}: mean |.| = {np.nanmean(np.abs(m)):.3g} mD")
            fig.colorbar(im, ax=ax, fraction=0.046, pad=0.02, label="mD")
    for ax in axes.ravel():
        ax.set_xticks([])
        ax.set_yticks([])
    met = validation.metrics
    fig.suptitle(
        "ratios Analyzer/analytical: "
        + ", ".join(f"{k} {v:.3f}" for k, v in met["ratios"].items())
        + f"\nProcrustes rotation {met['procrustes']['rotation_deg']:+.3f} deg, scale {met['procrustes']['scale']:.4f}"
    )
    fig.tight_layout()
    return fig, axes
