"""Exact ray tracer: heightfield intersections, vector Snell refraction and the mirror law.

Every ray starts at the camera pinhole, meets the deformed front face (found by
Newton iteration on the analytic height field), refracts into the glass
(vector Snell law), meets the deformed back face, refracts out and travels in
a straight line to the backdrop plane. Rays whose front-face hit lies outside
the pane go straight; rays hitting the frame band are blocked. Nothing is
linearised: the only approximations are the Newton tolerance (1e-10 mm) and
floating point.

Reflection (``scene.viewing.mode == "reflection"``, :func:`_reflection_components`): the
same front-face hit, then the mirror law on the true surface normal
(``r = d - 2 (d . N) N``) and a straight line to the board on the camera's side; with
``viewing.back_face`` also the ghost (refracted in, reflected by the back face, refracted
out through the front face), with the Fresnel reflectances of unpolarised light
(:func:`fresnel_reflectance`) as the two rays' weights.

References
----------
Hecht, E. (2017). *Optics*, 5th ed., §4.4 (refraction), §5.5 (prisms).
Spencer, G. H. and Murty, M. V. R. K. (1962). General ray-tracing procedure.
*J. Opt. Soc. Am.* 52(6), 672-678 (vector form of Snell's law).
Paper §2.1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..scene import (
    FaceShape,
    Scene,
    landing_jacobian,
    pattern_intensity,
    pixel_directions,
    pixel_grid,
    straight_landing,
)
from .imaging import apply_imaging

__all__ = [
    "TraceResult",
    "Landing",
    "trace_rays",
    "landing_points",
    "render_intensity",
    "ExactTracer",
    "refract",
    "fresnel_reflectance",
    "strata",
    "GLASS",
]

MISSED, GLASS, BLOCKED = 0, 1, 2
_NEWTON_TOL_MM = 1e-10
_NEWTON_MAX_ITER = 40


@dataclass(frozen=True)
class TraceResult:
    """Rays traced to the backdrop.

    Attributes
    ----------
    landing_mm : ndarray (N, 2)
        Backdrop landing points ``(X, Y)``, mm (NaN where blocked).
    status : ndarray (N,) of int8
        0: missed the pane (straight), 1: through the glass, 2: blocked (frame band or
        total internal reflection).
    """

    landing_mm: np.ndarray
    status: np.ndarray


@dataclass(frozen=True)
class Landing:
    """Per-pixel landing points of the pixel-centre lines of sight.

    Attributes
    ----------
    with_glass_mm, without_glass_mm : ndarray (H, W, 2)
        Landing points with and without the pane, backdrop mm.
    status : ndarray (H, W) of int8
        As :attr:`TraceResult.status`.
    """

    with_glass_mm: np.ndarray
    without_glass_mm: np.ndarray
    status: np.ndarray

    @property
    def displacement_mm(self) -> np.ndarray:
        """``delta = with - without`` (H, W, 2), mm; NaN where blocked."""
        return self.with_glass_mm - self.without_glass_mm


def refract(d: np.ndarray, normal: np.ndarray, eta) -> tuple[np.ndarray, np.ndarray]:
    """Vector Snell refraction.

    Parameters
    ----------
    d : ndarray (..., 3)
        Unit incident directions.
    normal : ndarray (..., 3)
        Unit surface normals oriented along the propagation (``d . N > 0``).
    eta : float or ndarray
        Ratio :math:`n_1 / n_2` of the indices before and after the surface.

    Returns
    -------
    t : ndarray (..., 3)
        Unit refracted directions.
    tir : ndarray of bool
        Total internal reflection (``t`` is then meaningless).

    Notes
    -----
    .. math::

       \\mathbf{t} = \\eta\\,\\mathbf{d} + \\left(\\sqrt{1 - \\eta^2 (1 - c^2)} - \\eta c\\right)\\mathbf{N},
       \\qquad c = \\mathbf{d}\\cdot\\mathbf{N}

    (Spencer and Murty 1962; Hecht 2017 §4.4).
    """
    c = np.einsum("...i,...i->...", d, normal)
    k = 1.0 - eta * eta * (1.0 - c * c)
    tir = k < 0
    t = eta * d + (np.sqrt(np.maximum(k, 0.0)) - eta * c)[..., None] * normal
    return t, tir


def _intersect(shape: FaceShape, w0: float, o, d) -> np.ndarray:
    """Ray parameter ``t`` where ``o + t d`` meets ``w = w0 + h(u, v)`` (Newton iteration).

    ``o`` and ``d`` are ``(u, v, w)`` component triples (arrays or scalars).
    """
    ou, ov, ow = o
    du, dv, dw = d
    t = (w0 - ow) / dw
    if not shape:
        return t
    for _ in range(_NEWTON_MAX_ITER):
        h, hu, hv = shape.height_gradient(ou + t * du, ov + t * dv)
        step = (ow + t * dw - w0 - h) / (dw - hu * du - hv * dv)
        t = t - step
        if not np.any(np.abs(step) > _NEWTON_TOL_MM):
            break
    return t


def _refract_c(d, g, eta):
    """:func:`refract` in components for the surface normal ``(-g_u, -g_v, 1) / norm``."""
    du, dv, dw = d
    gu, gv = g
    inv = 1.0 / np.sqrt(1.0 + gu * gu + gv * gv)
    nu, nv, nw = -gu * inv, -gv * inv, inv
    c = du * nu + dv * nv + dw * nw
    k = 1.0 - eta * eta * (1.0 - c * c)
    f = np.sqrt(np.maximum(k, 0.0)) - eta * c
    return (eta * du + f * nu, eta * dv + f * nv, eta * dw + f * nw), k < 0


def _front_hit(scene: Scene, dx, dy, dz):
    """Where rays from the camera meet the pane's front face (pane frame).

    Returns ``(o, (du, dv, dw), t, (pu, pv), inside, framed)``: the camera in pane
    coordinates, the directions in pane coordinates (``dw`` NaN for rays not heading into
    the pane), the ray parameter and in-plane hit point on the front face, the hits on the
    clear pane, and the hits on the frame band (None without a frame).
    """
    pane = scene.pane
    R = pane.rotation
    o = R.T @ (np.asarray(scene.camera.position_mm, float) - np.asarray(pane.center_mm, float))
    du = R[0, 0] * dx + R[1, 0] * dy + R[2, 0] * dz
    dv = R[0, 1] * dx + R[1, 1] * dy + R[2, 1] * dz
    dw = R[0, 2] * dx + R[1, 2] * dy + R[2, 2] * dz
    dw = np.where(dw > 1e-9, dw, np.nan)
    t = _intersect(pane.deformation.front_shape, -pane.thickness_mm / 2, o, (du, dv, dw))
    pu, pv = o[0] + t * du, o[1] + t * dv
    hw, hh = pane.size_mm[0] / 2, pane.size_mm[1] / 2
    inside = (np.abs(pu) <= hw) & (np.abs(pv) <= hh)
    framed = None
    if pane.frame is not None:
        fw = pane.frame.width_mm
        framed = inside & ((np.abs(pu) > hw - fw) | (np.abs(pv) > hh - fw))
        inside &= ~framed
    return o, (du, dv, dw), t, (pu, pv), inside, framed


def _trace_components(scene: Scene, dx, dy, dz):
    """Core of :func:`trace_rays` on flat component arrays; returns ``(X, Y, status)``."""
    cx, cy, cz = (float(a) for a in scene.camera.position_mm)
    s0 = (scene.backdrop_z_mm - cz) / dz
    X, Y = cx + s0 * dx, cy + s0 * dy
    status = np.zeros(dx.shape, np.int8)
    pane = scene.pane
    R = pane.rotation
    c = np.asarray(pane.center_mm, float)
    d = pane.thickness_mm
    n = pane.refractive_index
    front, back = pane.deformation.front_shape, pane.deformation.back_shape
    o, (du, dv, dw), t, (pu, pv), inside, framed = _front_hit(scene, dx, dy, dz)
    if not inside.all():
        idx = np.flatnonzero(inside)
        pu, pv, du, dv, dw, tt = pu[idx], pv[idx], du[idx], dv[idx], dw[idx], t[idx]
    else:
        idx, tt = None, t
    pw = o[2] + tt * dw
    b, tir1 = _refract_c((du, dv, dw), front.gradient(pu, pv), 1.0 / n)
    tb = _intersect(back, d / 2, (pu, pv, pw), b)
    qu, qv, qw = pu + tb * b[0], pv + tb * b[1], pw + tb * b[2]
    e, tir2 = _refract_c(b, back.gradient(qu, qv), n)
    ex = R[0, 0] * e[0] + R[0, 1] * e[1] + R[0, 2] * e[2]
    ey = R[1, 0] * e[0] + R[1, 1] * e[1] + R[1, 2] * e[2]
    ez = R[2, 0] * e[0] + R[2, 1] * e[1] + R[2, 2] * e[2]
    qx = c[0] + R[0, 0] * qu + R[0, 1] * qv + R[0, 2] * qw
    qy = c[1] + R[1, 0] * qu + R[1, 1] * qv + R[1, 2] * qw
    qz = c[2] + R[2, 0] * qu + R[2, 1] * qv + R[2, 2] * qw
    s1 = (scene.backdrop_z_mm - qz) / ez
    bad = tir1 | tir2 | ~(ez > 0)
    lx, ly = qx + s1 * ex, qy + s1 * ey
    st = np.where(bad, BLOCKED, GLASS).astype(np.int8)
    if idx is None:
        X, Y, status = lx, ly, st
    else:
        X[idx], Y[idx], status[idx] = lx, ly, st
    if framed is not None:
        status[framed] = BLOCKED
    blocked = status == BLOCKED
    X[blocked] = np.nan
    Y[blocked] = np.nan
    return X, Y, status


def fresnel_reflectance(cos_i, eta):
    """Reflectance of unpolarised light at a smooth interface (Fresnel equations).

    Parameters
    ----------
    cos_i : array_like
        Cosine of the angle of incidence (>= 0).
    eta : float
        ``n_1 / n_2``, the indices before and after the interface.

    Returns
    -------
    ndarray
        :math:`R = (r_s^2 + r_p^2)/2` with
        :math:`r_s = (\\eta\\cos i - \\cos t)/(\\eta\\cos i + \\cos t)`,
        :math:`r_p = (\\cos i - \\eta\\cos t)/(\\cos i + \\eta\\cos t)`,
        :math:`\\sin t = \\eta \\sin i`; 1 under total internal reflection
        (Hecht 2017 §4.6.2). Uncoated glass, n = 1.52, at normal incidence: 0.0426.
    """
    ci = np.abs(np.asarray(cos_i, float))
    k = 1.0 - eta * eta * (1.0 - ci * ci)
    ct = np.sqrt(np.maximum(k, 0.0))
    rs = (eta * ci - ct) / (eta * ci + ct)
    rp = (ci - eta * ct) / (ci + eta * ct)
    return np.where(k < 0, 1.0, 0.5 * (rs * rs + rp * rp))


def _normal_c(g):
    """Unit normal ``(-g_u, -g_v, 1) / norm`` (towards +w) of a face with slopes ``g``."""
    gu, gv = g
    inv = 1.0 / np.sqrt(1.0 + gu * gu + gv * gv)
    return -gu * inv, -gv * inv, inv


def _reflect_c(d, g):
    """Mirror law ``r = d - 2 (d . N) N`` in components, and ``|d . N|`` (the incidence cosine)."""
    n = _normal_c(g)
    c = d[0] * n[0] + d[1] * n[1] + d[2] * n[2]
    return tuple(d[i] - 2.0 * c * n[i] for i in range(3)), np.abs(c)


def _refract_c_signed(d, g, eta):
    """:func:`refract` in components with the face normal oriented along the propagation, and ``|d . N|``."""
    n = _normal_c(g)
    c = d[0] * n[0] + d[1] * n[1] + d[2] * n[2]
    sg = np.sign(c)
    c = np.abs(c)
    k = 1.0 - eta * eta * (1.0 - c * c)
    f = np.sqrt(np.maximum(k, 0.0)) - eta * c
    return tuple(eta * d[i] + f * sg * n[i] for i in range(3)), k < 0, c


def _to_board(scene: Scene, p, r):
    """World landing ``(X, Y)`` on the board plane of pane-frame rays ``p + s r``, and where they reach it."""
    R = scene.pane.rotation
    c = np.asarray(scene.pane.center_mm, float)
    w = [c[i] + R[i, 0] * p[0] + R[i, 1] * p[1] + R[i, 2] * p[2] for i in range(3)]
    e = [R[i, 0] * r[0] + R[i, 1] * r[1] + R[i, 2] * r[2] for i in range(3)]
    ok = e[2] < 0
    s = (scene.backdrop_z_mm - w[2]) / np.where(ok, e[2], -1.0)
    return w[0] + s * e[0], w[1] + s * e[1], ok


def _reflection_components(scene: Scene, dx, dy, dz):
    """Reflection branch of :func:`_trace_components`: rays reflected by the pane onto the board.

    Returns ``(X, Y, status, ghost)``: the front-face reflection's landing and status
    (0 missed the pane: no board seen, NaN; 1 reflected; 2 frame or a ray not returning
    to the board), and ``None`` or, with ``viewing.back_face``, ``(X2, Y2, w1, w2)``: the
    back face's landing and the Fresnel weights of the two rays.
    """
    pane = scene.pane
    d, n = pane.thickness_mm, pane.refractive_index
    front, back = pane.deformation.front_shape, pane.deformation.back_shape
    o, (du, dv, dw), t, (pu, pv), inside, framed = _front_hit(scene, dx, dy, dz)
    status = np.zeros(dx.shape, np.int8)
    if framed is not None:
        status[framed] = BLOCKED
    X, Y = np.full(dx.shape, np.nan), np.full(dx.shape, np.nan)
    idx = np.flatnonzero(inside)
    pu, pv, du, dv, dw, tt = pu[idx], pv[idx], du[idx], dv[idx], dw[idx], t[idx]
    p = (pu, pv, o[2] + tt * dw)
    g = front.gradient(pu, pv)
    r, cos_i = _reflect_c((du, dv, dw), g)
    lx, ly, ok = _to_board(scene, p, r)
    X[idx], Y[idx] = np.where(ok, lx, np.nan), np.where(ok, ly, np.nan)
    status[idx] = np.where(ok, GLASS, BLOCKED)
    if not scene.viewing.back_face:
        return X, Y, status, None
    b, tir1, _ = _refract_c_signed((du, dv, dw), g, 1.0 / n)
    tb = _intersect(back, d / 2, p, b)
    q = tuple(p[i] + tb * b[i] for i in range(3))
    gb = back.gradient(q[0], q[1])
    b2, cos_b = _reflect_c(b, gb)
    tf = _intersect(front, -d / 2, q, b2)
    f = tuple(q[i] + tf * b2[i] for i in range(3))
    gf = front.gradient(f[0], f[1])
    e, tir2, cos_f = _refract_c_signed(b2, gf, n)
    gx, gy, ok2 = _to_board(scene, f, e)
    ok2 &= ~(tir1 | tir2)
    w1 = fresnel_reflectance(cos_i, 1.0 / n)
    w2 = (1.0 - w1) * fresnel_reflectance(cos_b, n) * (1.0 - fresnel_reflectance(cos_f, n))
    X2, Y2, W1, W2 = (np.full(dx.shape, np.nan) for _ in range(4))
    X2[idx], Y2[idx] = np.where(ok2, gx, np.nan), np.where(ok2, gy, np.nan)
    W1[idx], W2[idx] = w1, np.where(ok2, w2, 0.0)
    return X, Y, status, (X2, Y2, W1, W2)


def trace_rays(scene: Scene, directions: np.ndarray, *, glass: bool = True) -> TraceResult:
    """Trace rays from the camera pinhole to the backdrop.

    Parameters
    ----------
    scene : Scene
    directions : ndarray (N, 3)
        Unit world directions of rays starting at ``scene.camera.position_mm``.
    glass : bool
        False traces the glass-less reference (every ray straight; in reflection, reflected
        by the flat plane of the nominal front face).

    Notes
    -----
    In reflection (``scene.reflection``) the landing points are the front face's
    reflection on the board (:func:`_reflection_components`); the back face's ghost enters
    the rendered image only.

    Returns
    -------
    TraceResult
    """
    directions = np.asarray(directions, float).reshape(-1, 3)
    if not glass:
        return TraceResult(straight_landing(scene, directions), np.zeros(len(directions), np.int8))
    comps = (directions[:, 0].copy(), directions[:, 1].copy(), directions[:, 2].copy())
    if scene.reflection:
        X, Y, status, _ = _reflection_components(scene, *comps)
    else:
        X, Y, status = _trace_components(scene, *comps)
    return TraceResult(np.stack([X, Y], axis=-1), status)


def landing_points(scene: Scene) -> Landing:
    """Exact landing points of every pixel-centre line of sight, with and without the glass.

    Returns
    -------
    Landing
        ``Landing.displacement_mm`` is the exact displacement field delta on the
        camera pixel grid (backdrop mm).

    Examples
    --------
    A flat 10 mm slab turned 20 deg shifts every line of sight sideways by about 1 mm:

    >>> from glassdist.render import landing_points
    >>> from glassdist.scene import scene_from_dict
    >>> scene = scene_from_dict({
    ...     "pane": {"size_mm": [2000, 1500], "thickness_mm": 10, "refractive_index": 1.5, "yaw_deg": 20},
    ...     "backdrop": {"pattern": "lines", "pitch_mm": 50, "line_width_mm": 10, "distance_m": 5},
    ...     "camera": {"focal_length_mm": 300, "sensor_width_mm": 36, "pixels": [64, 48], "position_mm": [0, 0, -3000]}})
    >>> landing = landing_points(scene)
    >>> landing.displacement_mm.shape, bool((landing.status == 1).all())  # all through the glass
    ((48, 64, 2), True)
    >>> dx_mm = landing.displacement_mm[..., 0]
    >>> round(float(dx_mm.min()), 2), round(float(dx_mm.max()), 2)  # larger at steeper incidence
    (1.0, 1.45)
    """
    col, row = pixel_grid(scene.camera)
    dirs = pixel_directions(scene.camera, col, row)
    H, W = scene.camera.shape
    res = trace_rays(scene, dirs.reshape(-1, 3))
    without = straight_landing(scene, dirs)
    return Landing(res.landing_mm.reshape(H, W, 2), without, res.status.reshape(H, W))


def strata(samples_per_pixel: int) -> tuple[int, int]:
    """Stratification ``(sx, sy)`` with ``sx * sy = spp`` as square as possible."""
    sy = int(math.isqrt(samples_per_pixel))
    while samples_per_pixel % sy:
        sy -= 1
    return samples_per_pixel // sy, sy


def render_intensity(
    scene: Scene,
    *,
    reference: bool,
    rng: np.random.Generator,
    samples_per_pixel: int,
    chunk_rays: int = 1 << 18,
    progress: Callable[[int, int], None] | None = None,
) -> np.ndarray:
    """Noise-free radiance image (H, W) in [0, 1] by jittered stratified supersampling.

    Each pixel is split into ``sx x sy`` strata (:func:`strata`); one ray per
    stratum at a uniformly jittered position. Each ray samples the backdrop
    box-filtered over the stratum's glass-less footprint (an exact box integral
    of the pattern, :func:`glassdist.scene.pattern_intensity`), which removes the
    line-position bias regular supersampling leaves (about 0.1 px) and the
    residual aliasing of point samples.
    """
    H, W = scene.camera.shape
    sx, sy = strata(samples_per_pixel)
    ss = np.arange(samples_per_pixel)
    ox, oy = (ss % sx + 0.0) / sx, (ss // sx + 0.0) / sy
    rows_per_chunk = max(1, chunk_rays // (W * samples_per_pixel))
    theta = math.radians(scene.backdrop.rotation_deg)
    rot = np.array([[math.cos(theta), math.sin(theta)], [-math.sin(theta), math.cos(theta)]])
    pane = scene.pane
    frame_I = pane.frame.intensity if pane.frame is not None else 0.0
    out = np.empty((H, W))
    for r0 in range(0, H, rows_per_chunk):
        r1 = min(H, r0 + rows_per_chunk)
        row, col = np.mgrid[r0:r1, 0:W].astype(float)
        Jp = rot @ landing_jacobian(scene, col + 0.5, row + 0.5)
        hx = 0.5 * (np.abs(Jp[..., 0, 0]) / sx + np.abs(Jp[..., 0, 1]) / sy)
        hy = 0.5 * (np.abs(Jp[..., 1, 0]) / sx + np.abs(Jp[..., 1, 1]) / sy)
        jit = rng.random((2, r1 - r0, W, samples_per_pixel))
        cs = col[..., None] + ox + jit[0] / sx
        rs = row[..., None] + oy + jit[1] / sy
        dirs = pixel_directions(scene.camera, cs.ravel(), rs.ravel())
        dx, dy, dz = dirs[:, 0].copy(), dirs[:, 1].copy(), dirs[:, 2].copy()
        del dirs
        if scene.reflection:
            centres = pixel_directions(scene.camera, (col[..., None] + ox + 0.5 / sx).ravel(),
                                       (row[..., None] + oy + 0.5 / sy).ravel())
            lum = _reflected_intensity(scene, dx, dy, dz, reference, (hx[..., None], hy[..., None]), cs.shape,
                                     centres)
            out[r0:r1] = lum.mean(axis=-1)
            if progress is not None:
                progress(r1 * W * samples_per_pixel, H * W * samples_per_pixel)
            continue
        if reference:
            s0 = (scene.backdrop_z_mm - scene.camera.position_mm[2]) / dz
            Xx = scene.camera.position_mm[0] + s0 * dx
            Xy = scene.camera.position_mm[1] + s0 * dy
            status = np.zeros(dx.shape, np.int8)
        else:
            Xx, Xy, status = _trace_components(scene, dx, dy, dz)
        Xx, Xy, status = (a.reshape(cs.shape) for a in (Xx, Xy, status))
        lum = pattern_intensity(scene.backdrop, Xx, Xy, (hx[..., None], hy[..., None]))
        lum = np.where(status == GLASS, lum * pane.transmittance, lum)
        lum = np.where(status == BLOCKED, frame_I, lum)
        out[r0:r1] = lum.mean(axis=-1)
        if progress is not None:
            progress(r1 * W * samples_per_pixel, H * W * samples_per_pixel)
    return out


def _reflected_intensity(scene: Scene, dx, dy, dz, reference: bool, half_width, shape, centres) -> np.ndarray:
    """Board radiance seen in the pane along rays ``(dx, dy, dz)`` (reflection), reshaped to ``shape``.

    Each ray stands for its stratum (:func:`render_intensity`): the board is box-filtered
    over the stratum's glass-less footprint, centred where the stratum's centre
    (``centres``, unit directions) lands without the glass, moved by the ray's own
    displacement ``delta = X(ray) - X_0(ray)`` (traced minus glass-less landing at the
    jittered point). The boxes of a pixel's strata then tile its footprint, so the
    reference (``delta = 0``) is the exact pixel-area integral of the board, and the pane's
    image differs from an exact area integral only by the variation of ``delta`` within a
    stratum (its strain times the stratum's size): the jitter samples the distortion, not
    the grid's lines, whose edges would otherwise add a sampling noise of several percent
    of the contrast at a few samples per pixel (a camera integrates its pixel area without
    such noise; sensor noise is :mod:`glassdist.render.imaging`'s).

    The reference is the board in the flat reference surface (the front face's nominal
    plane); the pane's image is the front-face reflection, or with ``viewing.back_face``
    the Fresnel-weighted mean ``(w1 I(X1) + w2 I(X2)) / (w1 + w2)`` of the front and back
    reflections. Where no board is seen (off the pane), the frame's intensity (0 without one).
    """
    pane = scene.pane
    frame_I = pane.frame.intensity if pane.frame is not None else 0.0
    Lc = straight_landing(scene, centres)
    if reference:
        return pattern_intensity(scene.backdrop, Lc[:, 0].reshape(shape), Lc[:, 1].reshape(shape), half_width)
    L0 = straight_landing(scene, np.stack([dx, dy, dz], axis=-1))
    shift_x, shift_y = (Lc[:, 0] - L0[:, 0]).reshape(shape), (Lc[:, 1] - L0[:, 1]).reshape(shape)
    X, Y, status, ghost = _reflection_components(scene, dx, dy, dz)
    X, Y, status = (a.reshape(shape) for a in (X, Y, status))
    lum = pattern_intensity(scene.backdrop, np.nan_to_num(X) + shift_x, np.nan_to_num(Y) + shift_y, half_width)
    if ghost is not None:
        X2, Y2, w1, w2 = (a.reshape(shape) for a in ghost)
        I2 = pattern_intensity(scene.backdrop, np.nan_to_num(X2) + shift_x, np.nan_to_num(Y2) + shift_y, half_width)
        w2 = np.nan_to_num(w2)
        lum = (w1 * lum + w2 * I2) / np.where(w1 + w2 > 0, w1 + w2, 1.0)
    return np.where(status == GLASS, lum, frame_I)


class ExactTracer:
    """The built-in exact engine (vectorised NumPy ray tracer); see :mod:`glassdist.render`."""

    name = "exact"

    def render(
        self,
        scene: Scene,
        *,
        reference: bool,
        rng: np.random.Generator,
        progress: Callable[[int, int], None] | None = None,
    ) -> np.ndarray:
        """Render the distorted (``reference=False``) or glass-less image, (H, W) in [0, 1]."""
        img = render_intensity(
            scene,
            reference=reference,
            rng=rng,
            samples_per_pixel=scene.render.samples_per_pixel,
            progress=progress,
        )
        return apply_imaging(img, scene.imaging, rng)

    def landing_points(self, scene: Scene) -> Landing:
        """Exact per-pixel landing points (see :func:`landing_points`)."""
        return landing_points(scene)
