"""
A control chart of a lot
========================

Eight panes of one lot, each analysed and written with its lot and pane id, land in a results
history (a throw-away SQLite file here; ``GLASSDIST_DB`` or ``--db`` on a line). The control
chart is the lot's 95th percentile of the absolute φ_eff run after run, its mean and its ±3σ limits. A drift of the
roller amplitude in the last panes shows as a rising run above the centre line. The limits are
computed from the lot's own runs (as ``glassdist history --chart`` does), so in a lot of n runs no
single run can lie more than (n − 1)/√n standard deviations from the mean — 2.47 for these
eight: a short lot's chart is read for trends, not for points beyond the limits.

The panes are synthetic captures (:mod:`glassdist.synthetic`: a line grid displaced by a known
roller wave) so that the eight analyses are quick.
"""

import shutil
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import glassdist
from glassdist.history import Recording, trends
from glassdist.synthetic import synthetic_capture, wave_displacement

rng = np.random.default_rng(3)
amplitudes_mm = np.r_[0.20 + 0.01 * rng.standard_normal(6), 0.25, 0.29]  # drifting at the end
folder = Path(tempfile.mkdtemp())
db = folder / "history.sqlite"
for i, amplitude in enumerate(amplitudes_mm):
    capture = synthetic_capture((160, 224), pitch_mm=6.0, mm_per_px=1.0, noise_std=0.01, rng=i,
                                displacement=wave_displacement(amplitude, 90.0, direction_deg=10.0))
    result = glassdist.analyze(capture.image, reference=capture.reference, pitch_mm=6.0, distance_m=2.0)
    glassdist.write_outputs(result, folder / f"pane_{i:02d}", metadata={"lot": "L-07", "pane_id": f"P-{i:02d}"},
                            history=Recording(db=str(db)))

# %%
# The lot's runs from the history and their control limits (:func:`glassdist.history.trends`,
# the computation behind ``glassdist history --chart``).
runs = glassdist.history(db, as_frame=False, lot="L-07")
chart = trends(runs)[0]
print(f"{len(runs)} runs; mean {chart.mean:.2f} mD, limits {chart.lower:.2f} to {chart.upper:.2f} mD")

x = np.arange(1, chart.values.size + 1)
fig, ax = plt.subplots(figsize=(8, 3.4), constrained_layout=True)
ax.plot(x, chart.values, "o-", color="#24384f", ms=4, lw=0.8, label="run")
ax.axhline(chart.mean, color="k", lw=1, label=f"mean {chart.mean:.2f} mD")
ax.axhline(chart.upper, color="k", lw=0.8, ls="--", label="±3σ")
ax.axhline(chart.lower, color="k", lw=0.8, ls="--")
if chart.out.any():
    ax.plot(x[chart.out], chart.values[chart.out], "o", ms=9, mfc="none", mec="red", label="beyond a limit")
ax.set_xticks(x, [r["pane_id"] for r in runs], rotation=45)
ax.set_xlabel("pane of lot L-07, in recording order")
ax.set_ylabel("p95 |φ_eff|, mD")
ax.legend(loc="upper left", fontsize=8)
plt.show()

shutil.rmtree(folder)  # the panes' outputs and the throw-away history
