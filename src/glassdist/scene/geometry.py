"""Scene geometry shared by the renderers and the analytical model.

Camera rays, pane-local frames, the glass-less (straight line) landing points
on the backdrop and their Jacobian, and the box-filtered backdrop pattern.
"""

from __future__ import annotations

import numpy as np

from .model import Backdrop, Camera, Scene

__all__ = [
    "pixel_directions",
    "pixel_grid",
    "straight_landing",
    "landing_jacobian",
    "pattern_coordinates",
    "pattern_intensity",
]


def pixel_directions(camera: Camera, col, row) -> np.ndarray:
    """Unit world directions of the lines of sight through image points.

    Parameters
    ----------
    camera : Camera
    col, row : array_like
        Continuous image coordinates in px; pixel ``(i, j)`` covers
        ``[j, j+1) x [i, i+1)``, so its centre is ``(j + 0.5, i + 0.5)``.

    Returns
    -------
    ndarray, shape ``broadcast(col, row).shape + (3,)``
        Unit vectors in the world frame.

    Notes
    -----
    Principal point at the image centre, square pixels of pitch :math:`p = s_w / W`,
    normalised image coordinates :math:`x_d = (c - W/2)\\,p/f`, :math:`y_d = (r - H/2)\\,p/f`;
    with Brown distortion :math:`D` (``camera.distortion``) they are undistorted first,
    :math:`(x, y) = D^{-1}(x_d, y_d)`, else :math:`(x, y) = (x_d, y_d)` (pinhole):

    .. math::

       \\mathbf{d}_{cam} = (x,\\ y,\\ 1), \\qquad
       \\mathbf{d} = R_{cam}\\,\\mathbf{d}_{cam} / \\lVert\\mathbf{d}_{cam}\\rVert .
    """
    H, W = camera.shape
    s = camera.pixel_pitch_mm / camera.focal_length_mm
    col, row = np.broadcast_arrays(np.asarray(col, float), np.asarray(row, float))
    x, y = (col - W / 2) * s, (row - H / 2) * s
    if camera.distortion is not None:
        x, y = camera.distortion.brown.undistort(x, y)
    d = np.stack([x, y, np.ones(col.shape)], axis=-1)
    d = d @ camera.rotation.T
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def pixel_grid(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Pixel-centre coordinates ``(col, row)``, each of shape (H, W), in px."""
    H, W = camera.shape
    row, col = np.mgrid[0:H, 0:W].astype(float)
    return col + 0.5, row + 0.5


def straight_landing(scene: Scene, directions: np.ndarray) -> np.ndarray:
    """Backdrop landing points ``(X, Y)`` in mm of rays from the camera without the glass.

    In transmission the rays go straight; in reflection (``scene.reflection``) they reflect
    in the flat plane of the nominal front face (``w = -d/2``, the flat reference surface)
    and land on the board: with ``p`` the hit point and ``w`` the pane normal,
    ``r = a - 2 (a . w) w``, ``X = p + r (z_b - p_z) / r_z``.
    """
    c = np.asarray(scene.camera.position_mm, float)
    if scene.reflection:
        pane = scene.pane
        w = pane.rotation[:, 2]
        plane_pt = np.asarray(pane.center_mm, float) - 0.5 * pane.thickness_mm * w
        a = np.asarray(directions, float)
        aw = a @ w
        p = c + (((plane_pt - c) @ w) / aw)[..., None] * a
        r = a - 2.0 * aw[..., None] * w
        t = (scene.backdrop_z_mm - p[..., 2]) / r[..., 2]
        return p[..., :2] + t[..., None] * r[..., :2]
    t = (scene.backdrop_z_mm - c[2]) / directions[..., 2]
    return c[:2] + t[..., None] * directions[..., :2]


def landing_jacobian(scene: Scene, col=None, row=None) -> np.ndarray:
    """Jacobian of the glass-less pixel -> backdrop mapping, mm per px.

    Returns ``J`` of shape ``(..., 2, 2)`` with ``J[..., a, b] = dX_a / dr_b``,
    ``r = (col, row)``, by central differences of :func:`straight_landing`
    (exact to rounding for the projective map at a half-pixel step).
    """
    if col is None:
        col, row = pixel_grid(scene.camera)
    h = 0.5
    cam = scene.camera
    dx = straight_landing(scene, pixel_directions(cam, col + h, row)) - straight_landing(
        scene, pixel_directions(cam, col - h, row)
    )
    dy = straight_landing(scene, pixel_directions(cam, col, row + h)) - straight_landing(
        scene, pixel_directions(cam, col, row - h)
    )
    return np.stack([dx, dy], axis=-1) / (2 * h)


def pattern_coordinates(backdrop: Backdrop, X, Y):
    """Pattern coordinates ``p = Rot(-theta) (X - offset)`` (mm) of backdrop points."""
    t = np.radians(backdrop.rotation_deg)
    x = X - backdrop.offset_mm[0]
    y = Y - backdrop.offset_mm[1]
    return np.cos(t) * x + np.sin(t) * y, -np.sin(t) * x + np.cos(t) * y


def _box_mean(cum, x, half, point):
    """Mean over ``[x - half, x + half]`` of a periodic profile with antiderivative ``cum``; ``point()``,
    the profile at ``x``, where ``half`` is 0 (point sampling)."""
    wide = half > 1e-12
    if np.all(wide):  # a footprint everywhere (the renders' case): no point samples to compute
        return (cum(x + half) - cum(x - half)) / (2 * half)
    safe = np.where(wide, half, 1.0)
    box = (cum(x + safe) - cum(x - safe)) / (2 * safe)
    return np.where(wide, box, point())


def _line_cover(x, half, pitch, width):
    """Mean of the periodic line indicator over ``[x - half, x + half]``."""

    def cum(s):
        s = s + width / 2
        return np.floor(s / pitch) * width + np.minimum(np.mod(s, pitch), width)

    return _box_mean(cum, x, half, lambda: (np.mod(x + width / 2, pitch) < width).astype(float))


def _square_wave_mean(x, half, q):
    """Mean of the +-1 square wave of half-period ``q`` (+1 on [0, q)) over ``[x-half, x+half]``."""

    def cum(s):
        m = np.mod(s, 2 * q)
        return np.minimum(m, 2 * q - m)

    return _box_mean(cum, x, half, lambda: np.where(np.mod(x, 2 * q) < q, 1.0, -1.0))


def _dot_cover(x: np.ndarray, y: np.ndarray, hx: np.ndarray | float, hy: np.ndarray | float, pitch: float,
               diameter: float) -> np.ndarray:
    """Cover of the dot lattice over a box of half-widths ``(hx, hy)``: the edge's ramp along its normal."""
    dx = x - pitch * np.round(x / pitch)
    dy = y - pitch * np.round(y / pitch)
    rho = np.hypot(dx, dy)
    safe = np.maximum(rho, 1e-12)
    half = np.abs(dx / safe) * hx + np.abs(dy / safe) * hy  # the box's half-extent along the radius
    inside = (rho < diameter / 2).astype(float)
    # A ramp of half-width h centred on radius r' covers pi (r'^2 + h^2 / 3): centred on
    # r' = sqrt(r^2 - h^2 / 3) it keeps the dot's area (the box filter's mean).
    edge = np.sqrt(np.maximum((diameter / 2) ** 2 - half**2 / 3.0, 0.0))
    ramp = np.clip(0.5 + (edge - rho) / np.maximum(2 * half, 1e-12), 0.0, 1.0)
    return np.where(half > 1e-12, ramp, inside)


def pattern_intensity(backdrop: Backdrop, X, Y, half_width=(0.0, 0.0)) -> np.ndarray:
    """Backdrop intensity (linear, in [black, white]) box-filtered over a footprint.

    Parameters
    ----------
    backdrop : Backdrop
    X, Y : ndarray
        World backdrop coordinates, mm.
    half_width : (array_like, array_like)
        Half-widths of an axis-aligned box in *pattern* coordinates (mm) over
        which the pattern is averaged exactly (0: point sampling).

    Notes
    -----
    The line grid is :math:`I = w - (w - b)\\,[1 - (1 - c_x)(1 - c_y)]` with
    :math:`c_x, c_y` the box-averaged covers of the two line families, the
    checkerboard :math:`I = (w + b)/2 + (w - b)/2\\,\\bar S_x \\bar S_y` with
    :math:`\\bar S` the box-averaged square waves; both are exact box integrals
    (the checkerboard because it is separable). The dot lattice is :math:`I = w - (w - b)\\,c`
    with :math:`c` the dot's cover, the disk's edge box-filtered along its normal: a linear ramp
    of half-width :math:`|n_x| h_x + |n_y| h_y` across the edge (exact for a straight edge under
    a box of that projected width, its centre moved in so that the dot keeps its area; the
    curvature's finer effect over the footprint is neglected, a shading error only, since the
    landing points carry the geometry).
    """
    px, py = pattern_coordinates(backdrop, X, Y)
    hx, hy = half_width
    b, w = backdrop.black, backdrop.white
    if backdrop.pattern == "lines":
        cx = _line_cover(px, hx, backdrop.pitch_mm, backdrop.line_width_mm)
        cy = _line_cover(py, hy, backdrop.pitch_mm, backdrop.line_width_mm)
        return w - (w - b) * (1.0 - (1.0 - cx) * (1.0 - cy))
    if backdrop.pattern == "dots":
        assert backdrop.dot_diameter_mm is not None  # required by the model for dots
        return w - (w - b) * _dot_cover(px, py, hx, hy, backdrop.pitch_mm, backdrop.dot_diameter_mm)
    sx = _square_wave_mean(px, hx, backdrop.pitch_mm)
    sy = _square_wave_mean(py, hy, backdrop.pitch_mm)
    return 0.5 * (w + b) + 0.5 * (w - b) * sx * sy
