"""
A reflection board: roller waves seen in the pane
=================================================

A grid board standing before a tempered pane is photographed in its reflection
(``examples/scenes/roller_wave_reflection.yaml``). Roller waves, invisible through the glass
at this amplitude, show strongly in reflection: the channels are the reflective power on the
pane, from the board's geometry (:class:`glassdist.ReflectionGeometry`).
"""

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import glassdist
from glassdist.render import render_scene
from glassdist.scene import load_scene
from glassdist.theory import analysis_params, reflection_geometry

root = Path(glassdist.__file__).resolve().parents[2]  # the repository (src/ layout)
# the scene at a reduced pixel count and 4 samples per pixel: a few seconds to render
scene = load_scene(root / "examples" / "scenes" / "roller_wave_reflection.yaml")
scene = scene.with_changes(camera={"pixels": [384, 288]}, render={"samples_per_pixel": 4})
photo = render_scene(scene)
board = render_scene(scene, reference=True)
result = glassdist.analyze_reflection(photo, reference=board, pitch_mm=scene.backdrop.pitch_mm,
                                      geometry=reflection_geometry(scene), params=analysis_params(scene))

# %%
# The reflected board, then φ_eff and φ_shear in reflective power on the pane.
fig, axes = plt.subplots(1, 3, figsize=(13, 3.6), constrained_layout=True)
axes[0].imshow(photo, cmap="gray")
axes[0].set_title("the board reflected in the pane")
lim = np.nanpercentile(np.abs(result.phi_eff_mD), 99)
im = axes[1].imshow(result.phi_eff_mD, cmap="RdBu_r", vmin=-lim, vmax=lim)
fig.colorbar(im, ax=axes[1], label="φ_eff, mD")
axes[1].set_title("φ_eff (reflection)")
im = axes[2].imshow(result.phi_shear_mD, cmap="viridis", vmin=0, vmax=np.nanpercentile(result.phi_shear_mD, 99))
fig.colorbar(im, ax=axes[2], label="φ_shear, mD")
axes[2].set_title("φ_shear (reflection)")
for ax in axes:
    ax.set_axis_off()
plt.show()
