"""Block I: the camera lens's distortion, fitted with the homography (Direct Method).

A camera with lens distortion does not image the flat grid board projectively: the
pixel of a logical grid point ``(U, V)`` is

.. math::

   \\mathbf{p} = \\mathbf{c} + s\\,D\\big((H(U, V) - \\mathbf{c}) / s\\big),

with ``H`` the homography of an ideal pinhole, ``D`` the Brown distortion
(:class:`glassdist.brown.BrownDistortion`: radial ``k1, k2``, optionally tangential
``p1, p2``) about the principal point ``c`` (the image centre, optionally fitted) and
``s`` a normalising length (half the image diagonal; OpenCV's coefficients are those
for ``s`` = the focal length in px, :meth:`LensModel.opencv`). The grid is straight
and regular on the board, and a lens's distortion is global with this fixed form, while
glass distortion is local: fitted over the part of the view where the grid shows no
strain (:func:`glassdist.analyzer.homography.refit_with_lens`), the lens is measured
from the photo itself. The synthetic reference of the Direct Method is then
``(U, V) = H^{-1}(c + s D^{-1}((p - c) / s))`` at every pixel.

Identifiability. A homography absorbs a uniform scale, so a radially symmetric
distortion is told apart from it only by its growth with radius, which needs fitted
points spread from the centre out towards the corners. A radially symmetric glass
feature centred on the optical axis has the lens's own form: where the fitted part of
the view leaves such a feature (its residual is radially symmetric about ``c``), the
Analyzer says so (:func:`radial_ambiguity`) and keeps it as glass. A lens's profile is
global: refitted without the inner disc of the view, or without one quadrant about ``c``,
it must stay the same (:func:`radial_consistency`); a glass feature the fit took for the
lens moves it (a centred one when the inner disc is left out, an off-centre one with its
quadrant), and Block I then keeps the glass as glass and says why.

References
----------
D. C. Brown (1971), Photogramm. Eng. 37, 855 (close-range camera calibration); Z. Zhang
(2000), IEEE TPAMI 22, 1330 (calibration from a planar grid: homography + radial terms,
jointly refined by Levenberg-Marquardt); Hartley & Zisserman (2004), ch. 7.4.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..brown import BrownDistortion
from ..errors import InputError

__all__ = [
    "LensModel",
    "LensCalibration",
    "fit_lens_homography",
    "radial_ambiguity",
    "radial_profile_discrepancy",
    "radial_consistency",
    "read_camera_file",
    "calibration_from_camera_file",
]


@dataclass(frozen=True)
class LensModel:
    """Brown distortion about a principal point, in pixel coordinates.

    Attributes
    ----------
    distortion : BrownDistortion
        Coefficients for coordinates normalised by ``scale_px``.
    center_px : (float, float)
        Principal point ``(x, y)`` = (column, row), px (pixel centres at integers).
    scale_px : float
        Normalising length, px.
    """

    distortion: BrownDistortion
    center_px: tuple[float, float]
    scale_px: float

    def distort_px(self, x, y):
        """Distorted pixel of the undistorted (pinhole) pixel ``(x, y)``."""
        cx, cy, s = self.center_px[0], self.center_px[1], self.scale_px
        xd, yd = self.distortion.distort((np.asarray(x) - cx) / s, (np.asarray(y) - cy) / s)
        return cx + s * xd, cy + s * yd

    def undistort_px(self, x, y):
        """Undistorted (pinhole) pixel of the photo's pixel ``(x, y)``."""
        cx, cy, s = self.center_px[0], self.center_px[1], self.scale_px
        xu, yu = self.distortion.undistort((np.asarray(x, float) - cx) / s, (np.asarray(y, float) - cy) / s)
        return cx + s * xu, cy + s * yu

    def opencv(self, focal_px: float) -> BrownDistortion:
        """The coefficients in OpenCV's convention (normalised by the focal length ``focal_px``, px)."""
        return self.distortion.rescaled(focal_px / self.scale_px)

    def corner_shift_px(self) -> float:
        """Radial shift of the distortion at normalised radius 1 (the image corner for the default scale), px."""
        return abs(self.scale_px * (self.distortion.k1 + self.distortion.k2))

    def to_dict(self) -> dict:
        """The record as a JSON-ready mapping."""
        return {**self.distortion.to_dict(), "center_px": list(self.center_px), "scale_px": self.scale_px}


@dataclass(frozen=True)
class LensCalibration:
    """The lens model Block I used, where it came from and how well it is determined.

    Attributes
    ----------
    model : LensModel
    source : str
        ``"self"`` (fitted from the photo's own grid), ``"photo"`` (a calibration photo of
        the grid without glass) or ``"file"`` (a camera file).
    sigma : dict
        Standard errors of the fitted coefficients (formal, from the fit's residuals; the
        residuals of neighbouring grid points are correlated, so these are lower bounds).
    identifiable : bool
        Whether the fitted points constrain the model (enough of them, spread out to
        ``min_radius`` of the view's corners); otherwise the lens is not applied.
    fit_fraction : float
        Share of the view's grid samples the model was fitted on (the unstrained part).
    rms_px : float
        RMS reprojection residual of the fitted samples, px.
    focal_px : float or None
        Focal length in px where known (camera file), for OpenCV's coefficients.
    note : str
        Why the model is not identifiable, or ``""``.
    consistency : dict
        Self-calibration only: how far the radial profile moves when the fit leaves out the
        inner disc (``"inner"``) or the worst quadrant (``"quadrants"``) of the view
        (:func:`radial_consistency`; a camera lens's distortion is global).
    gain : float
        Self-calibration only: the share of what a bare homography leaves on the fitted samples
        that the lens terms explain (NaN where not measured).
    floor : dict
        Calibration photo only: that photo (no glass) read by the Direct Method through this
        lens, at the analysis's detrend degree, smoothing and distance L:
        ``mean_abs_phi_eff_mD`` and ``p95_abs_phi_eff_mD`` over its trusted pixels, with
        ``phi_eff_sigma_mD`` (its median noise) and ``detrend_degree``, ``distance_m``. What the
        board and the camera leave against the perfect grid and the lens model, glass aside:
        the Direct Method's floor on that rig (:func:`glassdist.analyzer.calibrate.calibrate_from_photo`).
    """

    model: LensModel
    source: str
    sigma: dict = field(default_factory=dict)
    identifiable: bool = True
    fit_fraction: float = 1.0
    rms_px: float = float("nan")
    focal_px: float | None = None
    note: str = ""
    consistency: dict = field(default_factory=dict)
    floor: dict = field(default_factory=dict)
    gain: float = float("nan")

    def to_dict(self) -> dict:
        """The record as a JSON-ready mapping."""
        d = {"source": self.source, "model": self.model.to_dict(), "sigma": dict(self.sigma),
             "identifiable": self.identifiable, "fit_fraction": self.fit_fraction, "rms_px": self.rms_px,
             "corner_shift_px": self.model.corner_shift_px(), "note": self.note}
        if self.consistency:
            d["consistency"] = dict(self.consistency)
        if self.floor:
            d["floor"] = dict(self.floor)
        if self.focal_px is not None:
            d["focal_px"] = self.focal_px
            d["opencv"] = self.model.opencv(self.focal_px).to_dict()
        return d


def _normaliser(pts: np.ndarray) -> np.ndarray:
    """Hartley's similarity: centroid to the origin, mean distance sqrt(2)."""
    m = pts.mean(axis=0)
    d = float(np.mean(np.linalg.norm(pts - m, axis=1))) or 1.0
    k = np.sqrt(2.0) / d
    return np.array([[k, 0, -k * m[0]], [0, k, -k * m[1]], [0, 0, 1.0]])


def _project(H: np.ndarray, pts: np.ndarray) -> np.ndarray:
    q = np.c_[pts, np.ones(len(pts))] @ H.T
    return q[:, :2] / q[:, 2:3]


def _reprojection(sn, Tdi, dst, unpack, names):
    """The residual of :func:`fit_lens_homography` and its exact Jacobian, as two functions of the parameters.

    With ``q = H u`` (``u`` a Hartley-normalised grid point), ``p_n = (q_0, q_1) / q_2``, the
    undistorted pixel ``p_u = A p_n + b`` (``A, b`` from ``Tdi``), ``x = (p_u - c) / s`` and the
    residual ``r = (c + s D(x) - p) / s``:
    ``dr/dh = J_D A dp_n/dh / s``, ``dr/dk = dD/dk`` for each Brown coefficient, and
    ``dr/dc' = e - J_D e`` for the principal point ``c = c_0 + s c'``, with ``J_D`` the
    Jacobian of the Brown map (:meth:`glassdist.brown.BrownDistortion.jacobian`) at ``x``.
    Exact derivatives spare the fit the finite differences of ~10 residual evaluations per
    step; the minimum it reaches is the same.
    """
    A, b = Tdi[:2, :2], Tdi[:2, 2]
    n = len(sn)

    def parts(t):
        H = np.r_[t[:8], 1.0].reshape(3, 3)
        q = sn @ H.T
        pn = q[:, :2] / q[:, 2:3]
        _, lens = unpack(t)
        return q, pn, lens, pn @ A.T + b

    def fun(t):
        _, _, lens, pu = parts(t)
        xd, yd = lens.distort_px(pu[:, 0], pu[:, 1])
        return np.r_[xd - dst[:, 0], yd - dst[:, 1]] / lens.scale_px

    def jac(t):
        q, pn, lens, pu = parts(t)
        (cx, cy), s = lens.center_px, lens.scale_px
        x, y = (pu[:, 0] - cx) / s, (pu[:, 1] - cy) / s
        jxx, jxy, jyx, jyy = lens.distortion.jacobian(x, y)
        r2 = x * x + y * y
        # dp_n/dh: rows (x, y) over the 8 free entries of H
        w = 1.0 / q[:, 2]
        dpn = np.zeros((2, n, 8))
        dpn[0, :, 0:3] = sn * w[:, None]
        dpn[1, :, 3:6] = sn * w[:, None]
        dpn[0, :, 6:8] = -(pn[:, 0] * w)[:, None] * sn[:, :2]
        dpn[1, :, 6:8] = -(pn[:, 1] * w)[:, None] * sn[:, :2]
        dpu = np.einsum("ij,jnk->ink", A, dpn) / s
        J = np.empty((2 * n, 8 + len(names)))
        J[:n, :8] = jxx[:, None] * dpu[0] + jxy[:, None] * dpu[1]
        J[n:, :8] = jyx[:, None] * dpu[0] + jyy[:, None] * dpu[1]
        xy = x * y
        cols = {"k1": (x * r2, y * r2), "k2": (x * r2 * r2, y * r2 * r2), "p1": (2 * xy, r2 + 2 * y * y),
                "p2": (r2 + 2 * x * x, 2 * xy), "cx": (1.0 - jxx, -jyx), "cy": (-jxy, 1.0 - jyy)}
        for i, name in enumerate(names):
            J[:n, 8 + i], J[n:, 8 + i] = cols[name]
        return J

    return fun, jac


def fit_lens_homography(
    src: np.ndarray, dst: np.ndarray, H0: np.ndarray, *, center_px, scale_px: float, tangential: bool = False,
    principal_point: bool = False, start: BrownDistortion | None = None, fix_distortion: bool = False,
):
    """Homography and Brown distortion jointly, by Levenberg-Marquardt on the reprojection error.

    Minimises :math:`\\sum_i \\lVert c + s D((H(U_i, V_i) - c)/s) - p_i\\rVert^2` over the
    8 entries of ``H`` (Hartley-normalised), ``k1, k2`` and, if asked, ``p1, p2`` and the
    principal point, with the exact Jacobian (:func:`_reprojection`).

    Parameters
    ----------
    src, dst : ndarray (n, 2)
        Logical grid ``(U, V)`` and pixel ``(x, y)`` pairs.
    H0 : ndarray (3, 3)
        Starting homography.
    center_px : (float, float)
        Principal point (start value when ``principal_point``).
    scale_px : float
        Normalising length of the distortion coefficients, px.
    start : BrownDistortion, optional
        Starting distortion (held fixed with ``fix_distortion``: only ``H`` is fitted).

    Returns
    -------
    H : ndarray (3, 3)
    model : LensModel
    sigma : dict
        Formal standard errors of the distortion parameters.
    residual : ndarray (n,)
        Reprojection error of each point, px.
    """
    from scipy.optimize import least_squares

    src = np.asarray(src, float)
    dst = np.asarray(dst, float)
    Ts, Td = _normaliser(src), _normaliser(dst)
    Hn = Td @ H0 @ np.linalg.inv(Ts)
    Hn = Hn / Hn[2, 2]
    sn = np.c_[src, np.ones(len(src))] @ Ts.T
    Tdi = np.linalg.inv(Td)
    c0 = np.asarray(center_px, float)
    s = float(scale_px)
    b0 = start or BrownDistortion()
    if fix_distortion:
        names = []
        x0 = Hn.ravel()[:8]
    else:
        names = ["k1", "k2"] + (["p1", "p2"] if tangential else []) + (["cx", "cy"] if principal_point else [])
        x0 = np.r_[Hn.ravel()[:8], b0.k1, b0.k2, [b0.p1, b0.p2] if tangential else [], [0.0, 0.0] if principal_point else []]

    def unpack(t):
        H = Tdi @ np.r_[t[:8], 1.0].reshape(3, 3) @ Ts
        extra = {"k1": b0.k1, "k2": b0.k2, "p1": b0.p1, "p2": b0.p2, **dict(zip(names, t[8:]))}
        b = BrownDistortion(extra["k1"], extra["k2"], extra["p1"], extra["p2"])
        c = c0 + s * np.array([extra.get("cx", 0.0), extra.get("cy", 0.0)])
        return H, LensModel(b, (float(c[0]), float(c[1])), s)

    fun, jac = _reprojection(sn, Tdi, dst, unpack, names)
    sol = least_squares(fun, x0, jac=jac, method="lm", x_scale="jac", max_nfev=200 * len(x0))
    H, lens = unpack(sol.x)
    H = H / H[2, 2]
    r = sol.fun.reshape(2, -1) * s
    err = np.hypot(r[0], r[1])
    dof = max(2 * len(src) - len(x0), 1)
    var = float(np.sum(sol.fun**2)) / dof
    sigma = {}
    try:
        cov = np.linalg.inv(sol.jac.T @ sol.jac) * var
        sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
        sigma = {n: float(sd[8 + i]) for i, n in enumerate(names)}
        for n in ("cx", "cy"):
            if n in sigma:
                sigma[n] *= s  # px
    except np.linalg.LinAlgError:
        sigma = {n: float("inf") for n in names}
    return H, lens, sigma, err


def radial_ambiguity(residual_px: np.ndarray, dst: np.ndarray, center_px, scale_px: float, noise_px: float,
                     bins: int = 16) -> tuple[float, float]:
    """How much of the residual displacement left by the fit is radially symmetric about the principal point.

    The residual vectors ``e`` are projected on the radial direction ``(p - c)/|p - c|``;
    their mean over every ring of normalised radius (``bins`` rings) is the part a lens
    of higher order, or a glass feature centred on the optical axis, would show alike.

    Returns
    -------
    share : float
        Energy of the ring means over the residual's whole energy (0-1).
    rms_px : float
        RMS of the ring means, px (compare with ``noise_px``; returned as 0 below it).
    """
    e = np.asarray(residual_px, float)
    v = np.asarray(dst, float) - np.asarray(center_px, float)
    rho = np.linalg.norm(v, axis=1)
    ok = rho > 1e-9
    if ok.sum() < 4 * bins:
        return 0.0, 0.0
    er = np.sum(e[ok] * v[ok], axis=1) / rho[ok]
    idx = np.minimum((rho[ok] / scale_px * bins).astype(int), bins - 1)
    cnt = np.bincount(idx, minlength=bins)
    mean = np.bincount(idx, er, minlength=bins) / np.maximum(cnt, 1)
    sym = float(np.sum(cnt * mean**2))
    total = float(np.sum(e[ok] ** 2))
    rms = float(np.sqrt(sym / ok.sum()))
    if total <= 0 or rms < noise_px:
        return 0.0, 0.0
    return sym / total, rms


def radial_profile_discrepancy(a: BrownDistortion, b: BrownDistortion, radius: np.ndarray) -> float:
    """How far two radial distortion profiles differ, modulo the scale a homography absorbs.

    The radial shift of a Brown model at normalised radius ``r`` is
    :math:`\\delta(r) = r\\,(k_1 r^2 + k_2 r^4)`. A homography fitted with it takes any
    term linear in ``r`` (a uniform scale), so profiles are compared after removing their
    least-squares ``c r`` part, over the radii ``radius`` (normalised) of the fitted samples:

    .. math::

       d = \\frac{\\lVert (\\delta_a - \\delta_b)_\\perp \\rVert}{\\lVert (\\delta_a)_\\perp \\rVert},

    with :math:`(\\cdot)_\\perp` the part orthogonal to ``r``. 0: the same lens; 1: a profile
    as different from ``a`` as ``a`` is from no lens.
    """
    r = np.asarray(radius, float)

    def perp(d):
        return d - r * (np.sum(d * r) / max(float(np.sum(r * r)), 1e-300))

    da = perp(r * (a.k1 * r**2 + a.k2 * r**4))
    db = perp(r * (b.k1 * r**2 + b.k2 * r**4))
    na = float(np.linalg.norm(da))
    return float(np.linalg.norm(da - db) / na) if na > 0 else 0.0


def radial_consistency(src: np.ndarray, dst: np.ndarray, H: np.ndarray, lens: LensModel, *, inner: float = 0.5,
                       max_points: int = 1500, **opts) -> dict:
    """Whether the fitted lens is a global radial form or the trace of a local feature (leave-out refits).

    A camera lens's distortion is the same function of the radius in every part of the view;
    a glass feature's is local. The joint fit (:func:`fit_lens_homography`) is repeated with
    parts of the fitted samples left out: the inner disc (radius below ``inner`` times the
    samples' 95th-percentile radius about the principal point: a feature centred on the optical
    axis) and each quadrant about the principal point in turn (an off-centre feature), with the
    principal point held at the full fit's (the profiles are compared about one centre). Each
    refit's radial profile is compared with the full fit's
    (:func:`radial_profile_discrepancy`, over the full fit's sample radii).

    Parameters
    ----------
    src, dst : ndarray (n, 2)
        The fitted samples (logical grid, pixel).
    H, lens :
        The full fit (starting point of the refits).
    inner : float
        Radius of the left-out disc, share of the samples' 95th-percentile radius.
    max_points : int
        The refits use at most this many samples (a regular subsample).
    **opts
        ``scale_px``, ``tangential`` as for :func:`fit_lens_homography` (``principal_point`` is
        ignored: the refits keep the full fit's).

    Returns
    -------
    dict
        ``"inner"``: the discrepancy without the inner disc; ``"quadrants"``: the largest
        without one quadrant (NaN where too few samples are left).
    """
    src = np.asarray(src, float)
    dst = np.asarray(dst, float)
    if len(src) > max_points:
        k = np.arange(0, len(src), int(np.ceil(len(src) / max_points)))
        src, dst = src[k], dst[k]
    c = np.asarray(lens.center_px, float)
    v = dst - c
    rho = np.linalg.norm(v, axis=1)
    r_eval = rho / lens.scale_px
    r95 = float(np.percentile(rho, 95))
    subsets = {"inner": rho >= inner * r95}
    quad = (v[:, 0] >= 0).astype(int) + 2 * (v[:, 1] >= 0).astype(int)
    subsets.update({f"q{q}": quad != q for q in range(4)})
    out = {}
    for name, keep in subsets.items():
        if keep.sum() < 50 or np.percentile(rho[keep], 95) < 0.7 * r95:
            out[name] = float("nan")
            continue
        _, lk, _, _ = fit_lens_homography(src[keep], dst[keep], H, center_px=lens.center_px, start=lens.distortion,
                                          **{**opts, "principal_point": False})
        out[name] = radial_profile_discrepancy(lens.distortion, lk.distortion, r_eval)
    q = [out[f"q{i}"] for i in range(4) if np.isfinite(out[f"q{i}"])]
    return {"inner": out["inner"], "quadrants": max(q) if q else float("nan")}


def read_camera_file(path) -> tuple[np.ndarray, BrownDistortion, tuple[int, int] | None]:
    """An OpenCV-style camera file: camera matrix and distortion coefficients.

    Accepted: JSON or YAML with ``camera_matrix`` (3 x 3, or ``{"data": [9 values]}`` as
    OpenCV's FileStorage writes it) and ``dist_coeffs`` / ``distortion_coefficients``
    (``k1, k2, p1, p2[, k3]``; a non-zero ``k3`` is refused), optionally
    ``image_size`` / ``image_width``, ``image_height``. OpenCV's own YAML header
    (``%YAML:1.0``, ``!!opencv-matrix``) is read too.

    Returns
    -------
    K : ndarray (3, 3)
    distortion : BrownDistortion
        OpenCV's coefficients (normalised by the focal length).
    image_size : (width, height) or None

    Raises
    ------
    InputError
        One line saying what is missing or wrong.
    """
    from pathlib import Path

    from ..validation import load_mapping

    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read the camera file {p.name}: {exc.__class__.__name__}; "
                         "give a readable UTF-8 JSON/YAML file") from None
    if text.lstrip().startswith("%YAML"):  # OpenCV's FileStorage: drop its header and matrix tags
        import yaml

        text = "\n".join(ln for ln in text.splitlines() if not ln.startswith("%YAML")).replace("!!opencv-matrix", "")
        try:
            doc = yaml.safe_load(text)
        except yaml.YAMLError:
            doc = None
    else:
        doc = load_mapping(p, what="camera file")
    if not isinstance(doc, dict):
        raise InputError(f"camera file {p.name} is not a mapping with camera_matrix and dist_coeffs")

    def matrix(v, n):
        if isinstance(v, dict):
            v = v.get("data")
        a = np.asarray(v, dtype=float).ravel() if v is not None else np.empty(0)
        if a.size != n or not np.all(np.isfinite(a)):
            return None
        return a

    K = matrix(doc.get("camera_matrix"), 9)
    dist = doc.get("dist_coeffs", doc.get("distortion_coefficients"))
    dc = None
    if dist is not None:
        raw = dist.get("data") if isinstance(dist, dict) else dist
        dc = np.asarray(raw, dtype=float).ravel() if raw is not None else None
    if K is None or dc is None or dc.size < 4 or not np.all(np.isfinite(dc)):
        raise InputError(
            f"camera file {p.name} needs camera_matrix (3 x 3) and dist_coeffs (k1, k2, p1, p2[, k3]); "
            "write them as OpenCV's calibrateCamera returns them"
        )
    if dc.size > 4 and np.any(dc[4:] != 0):
        raise InputError(f"camera file {p.name}: only k1, k2, p1, p2 are modelled; k3 and beyond must be 0")
    K = K.reshape(3, 3)
    if K[0, 0] <= 0 or K[1, 1] <= 0 or abs(K[0, 0] / K[1, 1] - 1) > 0.01:
        raise InputError(f"camera file {p.name}: the camera matrix needs positive, equal focal lengths fx, fy (square pixels)")
    size = doc.get("image_size")
    if size is None and "image_width" in doc and "image_height" in doc:
        size = (doc["image_width"], doc["image_height"])
    size = None if size is None else (int(size[0]), int(size[1]))
    return K, BrownDistortion(*(float(c) for c in dc[:4])), size


def calibration_from_camera_file(path, image_shape: tuple[int, int]) -> LensCalibration:
    """The lens of an OpenCV-style camera file (:func:`read_camera_file`) for photos of ``image_shape`` ``(H, W)``.

    The coefficients keep OpenCV's normalisation (the focal length ``fx`` in px) and its
    principal point ``(cx, cy)`` (OpenCV's pixel centres are at integers, as here).

    Raises
    ------
    InputError
        When the file states an image size other than the photo's.
    """
    from pathlib import Path

    K, dist, size = read_camera_file(path)
    h, w = image_shape
    if size is not None and tuple(size) != (w, h):
        raise InputError(
            f"camera file {Path(path).name} is for {size[0]}x{size[1]} px photos but the photo is {w}x{h} px; "
            "calibrate the camera at the photo's resolution"
        )
    f = float(K[0, 0])
    return LensCalibration(LensModel(dist, (float(K[0, 2]), float(K[1, 2])), f), "file", focal_px=f)
