"""
One pane from the factory, the site and the street
==================================================

A tempered pane with a roller wave (0.6 mm, 400 mm) measured once on the factory line:
camera 3 m from the pane, the grid 1 m behind it (Comparative Method, ``--camera-distance-m
3``). What the same pane reads depends on where it is seen from: the capture's reading is
brought to the pane's own, intrinsic, channels (what an orthographic observer at normal
incidence reads), and ``glassdist.view`` predicts what ``analyze`` would report on a photo
taken by the site inspector (3 m away, the grid 0.5 m behind the installed pane) and what
an architect sees from the street (10 m away at 30 deg from the side, the street 50 m behind).
The same glass; the numbers differ by geometry alone (docs: "Viewpoint and flatness").
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import glassdist
from glassdist.render import render_scene
from glassdist.scene import scene_from_dict

Dc, L = 3.0, 1.0
W, H = 240, 180
half_view_mm = 500.0
mm_per_px = 2 * half_view_mm * (Dc + L) / Dc / W
pitch = round(12 * mm_per_px, 1)  # 12 px a period
scene = scene_from_dict({
    "pane": {"size_mm": [2400, 1800], "thickness_mm": 6, "refractive_index": 1.52,
             "deformation": {"front": [{"kind": "roller_wave", "amplitude_mm": 0.6, "wavelength_mm": 400}]}},
    "backdrop": {"pattern": "lines", "pitch_mm": pitch, "line_width_mm": pitch / 4, "distance_m": L},
    "camera": {"focal_length_mm": 18 * Dc * 1000 / half_view_mm, "sensor_width_mm": 36, "pixels": [W, H],
               "position_mm": [0, 0, -Dc * 1000]},
    "render": {"samples_per_pixel": 4, "seed": 1}})
sigma_mm = 40.0 * (Dc + L) / Dc  # 40 mm on the pane
factory = glassdist.analyze(render_scene(scene), reference=render_scene(scene, reference=True), pitch_mm=pitch,
                            distance_m=L, pattern="lines", sigma_mm=sigma_mm, detrend_degree=2)
out = Path(tempfile.mkdtemp()) / "factory"
glassdist.write_outputs(factory, out, camera_distance_m=Dc, fields="pixel")
stored = glassdist.load_result(out)

site = glassdist.view(out, observer_distance_m=3.0, background_distance_m=0.5)
street = glassdist.view(out, observer_distance_m=10.0, background_distance_m=50.0, viewing_angle_deg=30.0)

# %%
# The intrinsic reading (``summary.json`` ``intrinsic``) and the three views, each with the
# factor that carries the pane's own power to it (at the pane centre).
intrinsic = stored.summary["intrinsic"]
rows = [("factory (3 m, grid 1 m)", stored.summary["statistics"], intrinsic["capture_factor"]),
        ("site (3 m, grid 0.5 m)", site.statistics, site.factor),
        ("street (10 m at 30 deg, 50 m)", street.statistics, street.factor)]
print(f"intrinsic: mean |phi_eff| {intrinsic['phi_eff_mD']['mean_abs']:.1f} mD, "
      f"mean phi_shear {intrinsic['phi_shear_mD']['mean_abs']:.1f} mD")
for name, st, k in rows:
    print(f"{name:31s} mean |phi_eff| {st['phi_eff_mD']['mean_abs']:5.1f} mD, "
          f"mean phi_shear {st['phi_shear_mD']['mean_abs']:5.1f} mD (factor {k:.3f})")

# %%
# φ is the strain of the backdrop's image per metre of backdrop distance: from the street the
# pane's power reads less (the factor), but what the eye sees is the strain itself, φ Lo, and
# with the street 50 m behind that is far beyond the few per cent a photo's first-order reading
# holds to. The prediction says so.
for name, st, Lo in (("factory", rows[0][1], 1.0), ("site", site.statistics, 0.5), ("street", street.statistics, 50.0)):
    print(f"{name:8s} p95 strain of the backdrop's image {st['phi_total_mD']['p95_abs'] * Lo / 1000:.3f}")
for w in street.warnings:
    print("street:", w)

# %%
# The maps: the factory's φ_eff, the site's and the street's predicted photos (on their own
# pixel grids; the street's camera sees the pane foreshortened), one colour scale each.
fig, axes = plt.subplots(1, 3, figsize=(13, 3.6), constrained_layout=True)
maps = [(stored.pixel_field("phi_eff_mD"), "factory"), (site.phi_eff_mD, "site"), (street.phi_eff_mD, "street")]
for ax, (m, name) in zip(axes, maps):
    lim = np.nanpercentile(np.abs(m), 99)
    im = ax.imshow(m, cmap="RdBu_r", vmin=-lim, vmax=lim)
    ax.set_title(f"{name}: φ_eff, mD")
    ax.set_axis_off()
    fig.colorbar(im, ax=ax, shrink=0.8)
plt.show()
