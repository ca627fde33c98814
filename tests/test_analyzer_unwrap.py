"""F4: wrap then unwrap, residues, regions."""

import numpy as np
import pytest
from scipy import ndimage

from glassdist.analyzer.unwrap import branch_cuts, label_regions, residues, unwrap, wrap


def test_wrap_then_unwrap_recovers_smooth_phase():
    y, x = np.mgrid[0:120, 0:150].astype(float)
    true = 0.002 * (x - 60) ** 2 + 0.05 * y + 3 * np.sin(x / 20.0)  # spans many 2 pi
    valid = np.ones(true.shape, bool)
    labels, n = label_regions(valid)
    un = unwrap(wrap(true), valid, labels, n, seed=0)
    diff = un - true
    assert np.ptp(diff) < 1e-9  # exact up to one constant
    assert abs(diff.mean() / (2 * np.pi) - round(diff.mean() / (2 * np.pi))) < 1e-9


def test_two_regions_are_unwrapped_independently_with_small_offset():
    y, x = np.mgrid[0:80, 0:160].astype(float)
    true = 0.08 * x + 0.5
    valid = np.ones(true.shape, bool)
    valid[:, 78:84] = False  # a frame splits the view
    labels, n = label_regions(valid)
    assert n == 2
    un = unwrap(wrap(true), valid, labels, n, seed=0)
    for r in (1, 2):
        d = (un - true)[labels == r]
        assert np.ptp(d) < 1e-9
        assert np.abs(np.median(un[labels == r])) <= np.pi + 1e-9  # smallest-displacement choice


def test_residue_detected_at_a_phase_vortex():
    y, x = np.mgrid[0:40, 0:40].astype(float)
    vortex = np.arctan2(y - 20.3, x - 20.7)
    r = residues(vortex)
    assert r[20, 20] and r[21, 21]
    assert r.sum() == 4
    assert not residues(wrap(0.3 * x + 0.1 * y)).any()


def test_small_regions_dropped():
    valid = np.zeros((50, 50), bool)
    valid[:30, :30] = True
    valid[40:42, 40:42] = True
    labels, n = label_regions(valid, min_size=10)
    assert n == 1 and labels[41, 41] == 0


@pytest.mark.parametrize("k", [2, 4, 8])
def test_coarse_unwrap_is_exact_on_a_smooth_phase_with_a_hole(k):
    """The coarse path (every k-th sample unwrapped, the rest snapped to it) returns the exact phase.

    Called directly: ``unwrap`` falls back to the full-resolution unwrapper whenever the
    coarse result is inconsistent, so a broken coarse path would only cost time there.
    """
    from glassdist.analyzer.unwrap import _unwrap_coarse

    # 245 x 322: not multiples of k, so the coarse estimate is padded or cropped to the phase's shape
    y, x = np.mgrid[0:245, 0:322].astype(float)
    truth = 0.1 * x - 0.06 * y + 3.0 * np.sin(2 * np.pi * x / 150.0) * np.cos(2 * np.pi * y / 110.0)  # ~7 turns
    wrapped = np.angle(np.exp(1j * truth))
    valid = np.hypot(y - 120, x - 160) > 30  # an opaque drop: the coarse samples are filled across it
    un = _unwrap_coarse(wrapped, valid, 0, k)
    assert un is not None
    offset = un[valid] - truth[valid]
    assert np.allclose(offset, offset[0], atol=1e-9) and abs(offset[0] / (2 * np.pi) - round(offset[0] / (2 * np.pi))) < 1e-9
    assert np.all(np.isnan(un[~valid]))


def test_no_residue_on_a_steep_smooth_phase():
    """A plane phase stepping 2.0 rad per sample down and 2.5 across (wrapped steps still inside (-pi, pi]): every
    2 x 2 loop closes, no residue; each edge of the loop counts with its own sign (a flipped edge sums 4 rad)."""
    y, x = np.mgrid[0:40, 0:50].astype(float)
    assert not residues(wrap(2.0 * y + 2.5 * x)).any()
    assert not residues(wrap(-2.0 * y + 2.5 * x)).any()
    # a twisted phase: the step across turns from -3 to +3 rad down the view, each loop its own rows
    y, x = np.mgrid[0:40, 0:20].astype(float)
    assert not residues(wrap(3.0 * (2 * y / 40 - 1) * x)).any()


def test_wrap_is_the_principal_value():
    phase = np.linspace(-40.0, 40.0, 4001)
    w = wrap(phase)
    assert np.all((w >= -np.pi) & (w <= np.pi))
    turns = (phase - w) / (2 * np.pi)
    assert np.allclose(turns, np.round(turns), atol=1e-9)


def test_regions_are_numbered_by_decreasing_size_and_min_size_is_inclusive():
    valid = np.zeros((60, 60), bool)
    valid[:5, :4] = True  # 20 samples
    valid[10:30, 10:30] = True  # 400
    valid[40:50, 40:50] = True  # 100
    valid[55:57, 55:60] = True  # 10: exactly min_size
    labels, n = label_regions(valid, min_size=10)
    assert n == 4
    assert (labels[20, 20], labels[45, 45], labels[2, 2], labels[56, 57]) == (1, 2, 3, 4)
    assert label_regions(valid, min_size=11)[1] == 3
    labels, n = label_regions(np.zeros((5, 5), bool))
    assert n == 0 and not labels.any()
    lone = np.zeros((5, 5), bool)
    lone[2, 2] = True  # by default every region counts, a single sample too
    assert label_regions(lone)[1] == 1


def test_each_region_is_brought_to_the_smallest_displacement():
    """A ramp of ten turns, offset by 21 turns: whatever multiple of 2 pi the unwrapper starts from, the region's
    median is brought into (-pi, pi], for the first region as for the others."""
    y, x = np.mgrid[0:60, 0:200].astype(float)
    true = 42 * np.pi + 0.3 * x + 0.02 * y
    valid = np.ones(true.shape, bool)
    labels, n = label_regions(valid)
    un = unwrap(wrap(true), valid, labels, n, seed=0)
    assert np.ptp(un - true) < 1e-9
    assert -np.pi < np.median(un) <= np.pi


def test_coarse_unwrap_refuses_a_ridge_narrower_than_its_step():
    """A ridge of 4 rad, 3 samples wide, running down the view: the k = 8 estimate cannot follow it across, so the
    samples beside it snap a turn off and the phase jumps by more than pi along x only. The coarse path must see
    that and hand over (None), not return the jumps."""
    from glassdist.analyzer.unwrap import _unwrap_coarse

    y, x = np.mgrid[0:120, 0:200].astype(float)
    truth = 0.05 * x + 0.01 * y + 4.0 * np.exp(-(((x - 100) / 1.5) ** 2))
    valid = np.ones(truth.shape, bool)
    labels, n = label_regions(valid)
    for t in (truth, truth.T):  # the ridge across x, then across y
        assert _unwrap_coarse(wrap(t), valid.T if t is not truth else valid, 0, 8) is None
    un = unwrap(wrap(truth), valid, labels, n, seed=0)  # the full-resolution unwrapper follows it
    assert np.ptp(un - truth) < 1e-9


def _max_step(un: np.ndarray) -> float:
    """Largest phase step between 4-neighbours that are both unwrapped (NaN elsewhere), rad."""
    with np.errstate(invalid="ignore"):
        return float(max(np.nanmax(np.abs(np.diff(un, axis=0))), np.nanmax(np.abs(np.diff(un, axis=1)))))


def _unwrapped(phase, valid):
    labels, n = label_regions(valid)
    return unwrap(phase, valid, labels, n)


@pytest.mark.parametrize("turn", [0, 1, 2, 3])
def test_a_hole_the_phase_winds_around_is_cut_to_the_border_and_the_seam_lies_on_the_cut(turn):
    # A smooth field plus one turn around a point inside an excluded disc: every 2 x 2 loop of the
    # region closes, yet every loop around the disc turns by 2 pi. Without a cut the unwrapper puts a
    # whole-period seam where it likes inside the region; with it, the seam lies on the cut. The view
    # turned by 90 deg steps: the cut goes to each edge in turn.
    y, x = np.mgrid[0:120, 0:150].astype(float)
    phase = np.ascontiguousarray(np.rot90(wrap(0.2 * x + 0.1 * y + np.arctan2(y - 60.2, x - 80.3)), turn))
    valid = np.ascontiguousarray(np.rot90(np.hypot(y - 60, x - 80) > 12, turn))
    assert not residues(phase)[valid].any()
    assert _max_step(_unwrapped(phase, valid)) > np.pi
    cut = branch_cuts([phase], valid)
    assert cut.any() and not (cut & ~valid).any()
    # the shortest way out: from the disc's rim to the nearest border (the top, 48 samples away)
    assert 40 <= cut.sum() <= 52
    assert _max_step(_unwrapped(phase, valid & ~cut)) < np.pi


def test_two_opposite_holes_are_cut_to_each_other_and_a_neutral_hole_is_left_alone():
    y, x = np.mgrid[0:200, 0:200].astype(float)
    wind = np.arctan2(y - 100.3, x - 80.2) - np.arctan2(y - 100.3, x - 120.2)  # +1 and -1, 40 samples apart
    phase = wrap(0.3 * x - 0.2 * y + wind)
    neutral = np.hypot(y - 40, x - 150) <= 8  # a hole the phase does not wind around
    valid = (np.hypot(y - 100, x - 80) > 6) & (np.hypot(y - 100, x - 120) > 6) & ~neutral
    cut = branch_cuts([phase], valid)
    # one straight cut between the rims (40 - 2 x 6 samples), not two to the border (about 90 each)
    assert 26 <= cut.sum() <= 32
    assert not cut[neutral].any() and not ndimage.binary_dilation(neutral, iterations=3)[cut].any()
    assert _max_step(_unwrapped(phase, valid & ~cut)) < np.pi
    # a smooth phase needs no cut, holes or not
    assert not branch_cuts([wrap(0.3 * x - 0.2 * y)], valid).any()


def test_the_cut_holds_for_either_phase():
    # only the second carrier's phase winds: the hole is charged all the same
    y, x = np.mgrid[0:80, 0:80].astype(float)
    flat = wrap(0.25 * x)
    winding = wrap(0.25 * y + np.arctan2(y - 40.4, x - 40.3))
    valid = np.hypot(y - 40, x - 40) > 6
    assert branch_cuts([flat, winding], valid).any()
    assert not branch_cuts([flat, flat], valid).any()


def test_a_charged_hole_that_reaches_the_image_edge_needs_no_cut():
    # no loop of the region can go round it: nothing to cut (an excluded area at the edge is ground)
    y, x = np.mgrid[0:80, 0:100].astype(float)
    phase = wrap(0.2 * x + np.arctan2(y - 3.3, x - 50.2))
    valid = ~((np.abs(x - 50) <= 6) & (y <= 10))
    assert not branch_cuts([phase], valid).any()
    assert not branch_cuts([], np.hypot(y - 40, x - 50) > 6).any()


def test_like_charges_merge_and_go_to_the_nearest_edge_together():
    # two +1 holes 30 samples apart, the right one 25 samples from the right edge: joined (+2), then
    # cut to that edge, the way of the nearest excluded sample; the unwrapped region has no seam
    y, x = np.mgrid[0:120, 0:160].astype(float)
    phase = wrap(0.15 * y + np.arctan2(y - 60.3, x - 105.2) + np.arctan2(y - 60.3, x - 135.2))
    valid = (np.hypot(y - 60, x - 105) > 5) & (np.hypot(y - 60, x - 135) > 5)
    cut = branch_cuts([phase], valid)
    gap, out = 30 - 2 * 5 - 1, 160 - 1 - (135 + 5)
    assert gap + out - 2 <= cut.sum() <= gap + out + 2
    assert not cut[:, :100].any()  # nothing towards the far (left) edge
    assert _max_step(_unwrapped(phase, valid & ~cut)) < np.pi



@pytest.mark.parametrize("turn", [0, 1, 2, 3])
def test_a_charged_hole_is_cut_to_the_nearest_area_at_the_edge_past_a_neutral_one(turn):
    # a +1 hole; below it, 23 samples away, an excluded strip that reaches the bottom edge (ground); to
    # its right, 14 samples away, a neutral hole; the top edge 44 samples away. The cut goes down to the
    # strip, nowhere near the neutral hole, and the region unwraps without a seam. Turned by 90 deg steps
    # so that the strip meets each edge in turn.
    y, x = np.mgrid[0:120, 0:200].astype(float)
    phase = wrap(0.1 * x + 0.05 * y + np.arctan2(y - 50.3, x - 100.2))
    strip = (y >= 80) & (np.abs(x - 100) <= 5)
    neutral = np.hypot(y - 50, x - 125) <= 5
    valid = (np.hypot(y - 50, x - 100) > 6) & ~strip & ~neutral
    phase, valid, neutral = (np.ascontiguousarray(np.rot90(a, turn)) for a in (phase, valid, neutral))
    cut = branch_cuts([phase], valid)
    assert 21 <= cut.sum() <= 25
    assert not ndimage.binary_dilation(neutral, iterations=3)[cut].any()
    assert _max_step(_unwrapped(phase, valid & ~cut)) < np.pi


def test_a_region_riddled_with_charged_holes_is_cut_to_the_edge_at_once():
    # 80 vortices of either sign, each inside its own 6 x 6 excluded square: more than MAX_PAIRED_HOLES,
    # so each is cut straight to the edge in one pass (one distance transform); the region then
    # unwraps without a seam, where without the cuts it cannot
    from glassdist.analyzer.unwrap import MAX_PAIRED_HOLES

    rng = np.random.default_rng(3)
    n, m = 300, 80
    assert m > MAX_PAIRED_HOLES
    y, x = np.mgrid[0:n, 0:n].astype(float)
    cy, cx = rng.uniform(10, n - 10, m).astype(int), rng.uniform(10, n - 10, m).astype(int)
    sign = rng.choice([-1.0, 1.0], m)
    phase = wrap(0.2 * x + sum(s * np.arctan2(y - a - 0.3, x - b - 0.2) for a, b, s in zip(cy, cx, sign)))
    valid = np.ones((n, n), bool)
    for a, b in zip(cy, cx):
        valid[a - 2 : a + 4, b - 2 : b + 4] = False
    assert not residues(phase)[valid].any()
    assert _max_step(_unwrapped(phase, valid)) > np.pi
    cut = branch_cuts([phase], valid)
    assert _max_step(_unwrapped(phase, valid & ~cut)) < np.pi
