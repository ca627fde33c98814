"""F4: wrap then unwrap, residues, regions."""

import numpy as np

from glassdist.analyzer.unwrap import label_regions, residues, unwrap, wrap


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
