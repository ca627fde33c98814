"""Optical Theoretical Model: first-order Snell forward model of a deformed slab.

For each camera pixel the line of sight (direction :math:`\\mathbf a`, unit) is
followed through the *nominal* flat slab, and the deformations enter to first
order in the face heights and slopes. In pane coordinates (normal
:math:`\\hat w` towards the backdrop) let :math:`\\cos\\alpha = \\mathbf a\\cdot\\hat w`,
:math:`\\sin\\beta = \\sin\\alpha / n`, :math:`\\hat t` the in-plane direction of
incidence, :math:`\\hat s = \\hat w \\times \\hat t` and
:math:`\\hat m = \\cos\\alpha\\,\\hat t - \\sin\\alpha\\,\\hat w` (perpendicular to
:math:`\\mathbf a` in the plane of incidence). The ray meets the front face at
:math:`\\mathbf p_f` and leaves from the back face at
:math:`\\mathbf p_b = \\mathbf p_f + d\\tan\\beta\\,\\hat t`.

1. Flat-slab lateral shift (Hecht 2017 §4.4): the exit line is the incident
   line offset by :math:`\\mathbf D_0 = -s(\\alpha)\\,\\hat m`,
   :math:`s(\\alpha) = d\\sin(\\alpha-\\beta)/\\cos\\beta`.
2. Slab tilt (common slope :math:`\\mathbf g = \\nabla h_f(\\mathbf p_f)`): longitudinal and
   transverse prefactors,

   .. math::

      \\mathbf D_{tilt} = -\\frac{\\partial s}{\\partial\\alpha}(\\hat t\\cdot\\mathbf g)\\,\\hat m
      - d\\left(1 - \\frac{\\cos\\alpha}{n\\cos\\beta}\\right)(\\hat s\\cdot\\mathbf g)\\,\\hat s,

   both tending to :math:`-d(1-1/n)\\,\\mathbf g` at normal incidence.
3. Thickness change: :math:`\\mathbf D_{thick} = \\mathbf D_0\\,\\Delta t / d` with
   :math:`\\Delta t = h_b(\\mathbf p_b) - h_f(\\mathbf p_f) - \\mathbf g\\cdot(\\mathbf p_b - \\mathbf p_f)`,
   the back face's height above the front face's tangent plane at the exit point.
4. Thin prism from the non-conformal back face (Spencer and Murty 1962,
   linearised): with the wedge :math:`\\Delta\\mathbf g = \\nabla h_b(\\mathbf p_b) - \\nabla h_f(\\mathbf p_f)`
   (for a conformal sheet :math:`\\approx \\mathbf H_Z\\,d\\tan\\beta\\,\\hat t`, the
   Hessian times the in-glass lateral travel), the exit direction turns by

   .. math::

      \\delta\\mathbf e = K_0\\,\\Delta\\mathbf g
      - \\sin\\beta\\,(\\hat t\\cdot\\Delta\\mathbf g)\\left(\\frac{n^2\\cos\\beta}{\\cos\\alpha} - n\\right)\\hat w,
      \\qquad K_0 = n\\cos\\beta - \\cos\\alpha

   (towards the thicker side of the wedge; :math:`K_0 \\to n - 1` at normal incidence).
5. Propagation to the backdrop plane (normal :math:`\\hat z`) over the path
   length :math:`\\ell` from the exit point, with the oblique projection
   :math:`\\Pi\\mathbf v = \\mathbf v - \\mathbf a\\,v_z/a_z` (the
   :math:`\\sec\\alpha` projection factors):

   .. math::

      \\delta = \\Pi(\\mathbf D_0 + \\mathbf D_{tilt} + \\mathbf D_{thick}) + \\ell\\,\\Pi\\,\\delta\\mathbf e .

6. Pinhole projection: the model is evaluated on the lines of sight of the
   camera's pixel centres, so it lives on the camera pixel grid.

Reflection (``scene.reflection``, :func:`_predict_reflection`): the line of sight meets the
nominal front plane at :math:`\\mathbf p_f` and reflects to
:math:`\\mathbf r_0 = \\mathbf a - 2\\cos\\alpha\\,\\hat w`. The mirror law on the surface slope
(normal :math:`\\hat w - \\mathbf g`, :math:`\\mathbf g = \\nabla h_f`) turns it by
:math:`\\delta\\mathbf r = 2\\cos\\alpha\\,\\mathbf g + 2(\\mathbf a\\cdot\\mathbf g)\\,\\hat w`, and the
height moves the hit point along the line of sight by :math:`h_f/\\cos\\alpha`; carried to the
board with the oblique projection along :math:`\\mathbf r_0`,

.. math::

   \\delta = \\Pi_r\\!\\left(\\frac{h_f}{\\cos\\alpha}\\,\\mathbf a\\right) + \\ell\\,\\Pi_r\\,\\delta\\mathbf r ,

whose gradient gives Coddington's factors off the normal (``1/cos^2`` along the plane of
incidence: :mod:`glassdist.analyzer.reflection`). Terms ``height`` and ``slope``.

Term 1 is exact; terms 2-4 are linear in the face heights and slopes, so the
prediction of a sum of deformations is the sum of the predictions.

What the model neglects (all second order): products of slopes, heights and
curvatures; the shift of the sampling points by the deformation (the entry
point moves by :math:`\\tan\\alpha\\,h_f`, the exit point by
:math:`d\\sec^2\\beta\\,\\delta\\beta` when the slope turns the in-glass ray); the
change of the prefactors and of :math:`\\ell` with the perturbed angles. The
relative error of the prism term scales as :math:`|\\nabla h| / \\tan\\beta`
(see docs/explanation/virtual-pipeline.md for measured values).

References
----------
Hecht, E. (2017). *Optics*, 5th ed., §4.4, §5.5.
Spencer, G. H. and Murty, M. V. R. K. (1962). *J. Opt. Soc. Am.* 52(6), 672-678.
Paper §3.1.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..scene import Scene, landing_jacobian, pixel_directions, pixel_grid

__all__ = ["Prediction", "predict_displacement", "slab_shift", "nominal_mm_per_px"]

NO_GLASS, GLASS, BLOCKED = 0, 1, 2


@dataclass(frozen=True)
class Prediction:
    """The analytical model on the camera pixel grid.

    Attributes
    ----------
    displacement_mm : ndarray (H, W, 2)
        Predicted delta (landing with glass minus without), backdrop mm; NaN
        where the frame blocks the view.
    status : ndarray (H, W) of int8
        0: line of sight misses the pane (delta = 0), 1: through the glass, 2: frame.
    incidence_deg : ndarray (H, W)
        Angle of incidence alpha on the nominal pane, degrees.
    terms_mm : dict of str -> ndarray (H, W, 2)
        The additive parts of delta: ``slab`` (flat-slab shift), ``tilt``,
        ``thickness`` and ``prism``.
    """

    displacement_mm: np.ndarray
    status: np.ndarray
    incidence_deg: np.ndarray
    terms_mm: dict

    @property
    def valid(self) -> np.ndarray:
        """Pixels with a prediction (not blocked by the frame)."""
        return self.status != BLOCKED


def slab_shift(alpha_rad, thickness_mm: float, n: float):
    """Lateral shift of a flat slab and its derivatives.

    Returns
    -------
    s : ndarray
        :math:`s = d\\sin(\\alpha-\\beta)/\\cos\\beta`, mm.
    ds_dalpha : ndarray
        :math:`\\partial s/\\partial\\alpha = d\\,(\\cos\\alpha + \\sin\\alpha\\tan\\beta
        - \\cos\\alpha\\sec^2\\beta\\,\\cos\\alpha/(n\\cos\\beta))`, mm/rad.
    transverse : ndarray
        :math:`s/\\sin\\alpha = d\\,(1 - \\cos\\alpha/(n\\cos\\beta))`, mm/rad.
    """
    a = np.asarray(alpha_rad, float)
    sa, ca = np.sin(a), np.cos(a)
    sb = sa / n
    cb = np.sqrt(1 - sb * sb)
    tb = sb / cb
    d = thickness_mm
    s = d * (sa - ca * tb)
    ds = d * (ca + sa * tb - ca * ca / (cb * cb) / (n * cb))
    tr = d * (1 - ca / (n * cb))
    return s, ds, tr


class _Sight(NamedTuple):
    """Lines of sight through the nominal (flat) pane, in pane coordinates (u, v along the faces)."""

    tu: np.ndarray  # unit in-plane direction of the ray (its plane of incidence), u component
    tv: np.ndarray  # ... v component
    sa: np.ndarray  # sin(alpha), alpha the angle of incidence
    ca: np.ndarray  # cos(alpha)
    sb: np.ndarray  # sin(beta) = sin(alpha) / n, beta the angle of refraction
    cb: np.ndarray  # cos(beta)
    tb: np.ndarray  # tan(beta)
    pfu: np.ndarray  # entry point on the nominal front face w = -d/2, mm
    pfv: np.ndarray
    pbu: np.ndarray  # exit point on the nominal back face w = +d/2, mm
    pbv: np.ndarray


def _sight_through_pane(scene: Scene, a: np.ndarray) -> _Sight:
    """Incidence, refraction and the entry and exit points of world directions ``a`` (..., 3) from the camera."""
    pane = scene.pane
    R = pane.rotation
    d, n = pane.thickness_mm, pane.refractive_index
    o = (np.asarray(scene.camera.position_mm, float) - np.asarray(pane.center_mm, float)) @ R
    al = a @ R
    ca = al[..., 2]
    sa = np.hypot(al[..., 0], al[..., 1])
    tiny = sa < 1e-14
    safe = np.where(tiny, 1.0, sa)
    tu = np.where(tiny, 1.0, al[..., 0] / safe)
    tv = np.where(tiny, 0.0, al[..., 1] / safe)
    sb = sa / n
    cb = np.sqrt(1 - sb * sb)
    tb = sb / cb
    tf = (-d / 2 - o[2]) / ca
    pfu, pfv = o[0] + tf * al[..., 0], o[1] + tf * al[..., 1]
    pbu, pbv = pfu + d * tb * tu, pfv + d * tb * tv
    return _Sight(tu, tv, sa, ca, sb, cb, tb, pfu, pfv, pbu, pbv)


def _sight_status(pane, pfu: np.ndarray, pfv: np.ndarray) -> np.ndarray:
    """Status per line of sight from its front-face entry point: misses the pane, through the glass, frame."""
    hw, hh = pane.size_mm[0] / 2, pane.size_mm[1] / 2
    inside = (np.abs(pfu) <= hw) & (np.abs(pfv) <= hh)
    status = np.where(inside, GLASS, NO_GLASS).astype(np.int8)
    if pane.frame is not None:
        fw = pane.frame.width_mm
        status[inside & ((np.abs(pfu) > hw - fw) | (np.abs(pfv) > hh - fw))] = BLOCKED
    return status


def predict_displacement(scene: Scene, col=None, row=None) -> Prediction:
    """Evaluate the analytical forward model (module docstring) per pixel.

    Parameters
    ----------
    scene : Scene
    col, row : ndarray, optional
        Image coordinates (px) of the lines of sight; default the pixel centres.

    Returns
    -------
    Prediction

    Examples
    --------
    A 0.3 mm roller wave on a 20 mm slab turned 30 deg (64 x 48 px), model against exact tracer:

    >>> import numpy as np
    >>> from glassdist.render import landing_points
    >>> from glassdist.scene import scene_from_dict
    >>> from glassdist.theory import predict_displacement
    >>> scene = scene_from_dict({
    ...     "pane": {"size_mm": [1400, 1000], "thickness_mm": 20, "refractive_index": 1.52, "yaw_deg": 30,
    ...              "deformation": {"both": [{"kind": "roller_wave", "amplitude_mm": 0.3, "wavelength_mm": 200}]}},
    ...     "backdrop": {"pattern": "lines", "pitch_mm": 72.6, "line_width_mm": 18, "distance_m": 10},
    ...     "camera": {"focal_length_mm": 300, "sensor_width_mm": 36, "pixels": [64, 48], "position_mm": [0, 0, -4000]}})
    >>> model = predict_displacement(scene)
    >>> model.displacement_mm.shape, sorted(model.terms_mm)
    ((48, 64, 2), ['prism', 'slab', 'thickness', 'tilt'])
    >>> bool(np.abs(model.displacement_mm - landing_points(scene).displacement_mm).max() < 0.2)  # mm
    True
    """
    cam, pane = scene.camera, scene.pane
    if col is None:
        col, row = pixel_grid(cam)
    a = pixel_directions(cam, col, row)
    if scene.reflection:
        return _predict_reflection(scene, a)
    R = pane.rotation
    c = np.asarray(pane.center_mm, float)
    d, n = pane.thickness_mm, pane.refractive_index
    tu, tv, sa, ca, sb, cb, tb, pfu, pfv, pbu, pbv = _sight_through_pane(scene, a)
    su, sv = -tv, tu
    status = _sight_status(pane, pfu, pfv)

    front, back = pane.deformation.front_shape, pane.deformation.back_shape
    gfu, gfv = front.gradient(pfu, pfv)
    gbu, gbv = back.gradient(pbu, pbv)
    gt = tu * gfu + tv * gfv
    gs = su * gfu + sv * gfv
    # back-face height above the front face's tangent plane carried to the exit point
    dh = back.height(pbu, pbv) - front.height(pfu, pfv) - d * tb * gt

    s, ds, tr = slab_shift(np.arctan2(sa, ca), d, n)
    m = np.stack([ca * tu, ca * tv, -sa], axis=-1)
    shat = np.stack([su, sv, np.zeros_like(su)], axis=-1)
    D0 = -s[..., None] * m
    Dtilt = -(ds * gt)[..., None] * m - (tr * gs)[..., None] * shat
    Dthick = D0 * (dh / d)[..., None]
    K0 = n * cb - ca
    Dgu, Dgv = gbu - gfu, gbv - gfv
    de = np.stack([K0 * Dgu, K0 * Dgv, -sb * (tu * Dgu + tv * Dgv) * (n * n * cb / ca - n)], axis=-1)

    pb = np.stack([pbu, pbv, np.full(pbu.shape, d / 2)], axis=-1)
    exit_z = c[2] + pb @ R[2]
    ell = (scene.backdrop_z_mm - exit_z) / a[..., 2]

    def project(v_local):
        v = v_local @ R.T
        return v[..., :2] - a[..., :2] * (v[..., 2] / a[..., 2])[..., None]

    glass = (status == GLASS)[..., None]
    terms = {
        "slab": project(D0),
        "tilt": project(Dtilt),
        "thickness": project(Dthick),
        "prism": ell[..., None] * project(de),
    }
    terms = {k: np.where(glass, v, 0.0) for k, v in terms.items()}
    delta = sum(terms.values())
    delta = np.where((status == BLOCKED)[..., None], np.nan, delta)
    return Prediction(delta, status, np.degrees(np.arctan2(sa, ca)), terms)


def _predict_reflection(scene: Scene, a: np.ndarray) -> Prediction:
    """Reflection branch of :func:`predict_displacement` (module notes): mirror law on the front face's slope."""
    pane = scene.pane
    R = pane.rotation
    c = np.asarray(pane.center_mm, float)
    d = pane.thickness_mm
    sight = _sight_through_pane(scene, a)
    status = _sight_status(pane, sight.pfu, sight.pfv)
    front = pane.deformation.front_shape
    h = front.height(sight.pfu, sight.pfv)
    gu, gv = front.gradient(sight.pfu, sight.pfv)
    al = a @ R
    ca = al[..., 2]
    r0 = al * np.array([1.0, 1.0, -1.0])
    dr = np.stack([2 * ca * gu, 2 * ca * gv, 2 * (al[..., 0] * gu + al[..., 1] * gv)], axis=-1)
    dp = al * (h / ca)[..., None]
    p0 = c + np.stack([sight.pfu, sight.pfv, np.full(h.shape, -d / 2)], axis=-1) @ R.T
    r0w = r0 @ R.T
    ell = (scene.backdrop_z_mm - p0[..., 2]) / r0w[..., 2]

    def project(v_local):
        v = v_local @ R.T
        return v[..., :2] - r0w[..., :2] * (v[..., 2] / r0w[..., 2])[..., None]

    glass = (status == GLASS)[..., None]
    terms = {"height": project(dp), "slope": ell[..., None] * project(dr)}
    terms = {k: np.where(glass, v, 0.0) for k, v in terms.items()}
    delta = np.where((status == BLOCKED)[..., None], np.nan, sum(terms.values()))
    return Prediction(delta, status, np.degrees(np.arccos(np.clip(ca, -1.0, 1.0))), terms)


def nominal_mm_per_px(scene: Scene) -> float:
    """Median isotropic backdrop scale of the glass-less camera view, mm per px (sqrt |det J|)."""
    J = landing_jacobian(scene)
    return float(np.median(np.sqrt(np.abs(np.linalg.det(J)))))
