"""A1: the carrier phase maps as displacement on the backdrop (mm), then A2-A3 on it (paper §2.2, Block A).

Projective A1 (default): carrier *i* measures the displacement along backdrop grid axis *i*
exactly, ``delta_i = p_c phi_i / (2 pi)`` (``p_c`` the carrier period on the backdrop),
whatever the perspective; gradients are taken with respect to backdrop mm through the
Jacobian of the baseline homography (and lens), and the result is rotated into the camera
frame (x along columns, y along rows). Isotropic A1 (the paper's reporting convention): the
dual-basis inverse ``(M^T)^{-1}`` and the single scale ``mm_per_px = p_c sqrt(|f1||f2|)``.

:func:`components` computes the displacement and the Jacobian once per analysis (a
:class:`Components` record); :func:`channels` evaluates A2-A3 on it and says, in an
:class:`A1Map`, what maps the phases to the outputs (for the uncertainty).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from . import fourier as F
from .analysis_grid import AnalysisGrid
from .homography import logical_jacobian
from .lens import LensModel
from .metrics import Channels, evaluate_displacement, inverse_2x2
from .params import AnalyzerParams

__all__ = ["A1Map", "Channels", "ChannelEvaluation", "Components", "channels", "components", "polar_rotation"]


def polar_rotation(J: np.ndarray) -> np.ndarray:
    """The rotation of the polar decomposition of a 2 x 2 matrix ``J`` (``U V^T`` of its SVD)."""
    u, _, vt = np.linalg.svd(J)
    return u @ vt


@dataclass(frozen=True)
class Components:
    """A1's displacement on the analysis grid, before the rotation into the camera frame.

    Attributes
    ----------
    delta_mm : ndarray (h, w, 2)
        Grid-frame components ``phases * p_c / (2 pi)`` (projective), or camera-frame
        components (isotropic), backdrop mm.
    jacobian : ndarray (h, w, 2, 2) or None
        ``dX/dr`` (mm per px) of the baseline (and lens) the gradients are taken through; None:
        the isotropic scale ``mm_per_px``.
    frame_rotation : ndarray (2, 2) or None
        Component frame -> camera frame (the Jacobian's rotation at the grid's centre); None:
        already the camera frame.
    """

    delta_mm: np.ndarray
    jacobian: np.ndarray | None
    frame_rotation: np.ndarray | None


def components(ag: AnalysisGrid, ks: tuple[F.Carrier, F.Carrier], H_jac: np.ndarray, p: AnalyzerParams, p_c: float,
               mm_per_px: float, lens: LensModel | None = None) -> Components:
    """A1: the displacement (mm) Block A evaluates and the Jacobian its gradients take (:class:`Components`).

    ``"projective"``: grid-frame components ``phases * p_c / (2 pi)`` with ``dX/dr`` of the
    baseline ``H_jac`` (and ``lens``); else camera-frame components from the carriers, isotropic scale.
    """
    if p.a1_mode == "projective":
        yy, xx = ag.grid.coords()
        J = p_c * logical_jacobian(H_jac, lens, xx, yy)
        hc, wc = ag.grid.shape
        return Components(ag.phases * (p_c / (2 * np.pi)), J, polar_rotation(J[hc // 2, wc // 2]))
    M = np.array([ks[0].f / ks[0].norm, ks[1].f / ks[1].norm]).T  # columns: unit carriers
    proj_px = ag.phases / (2 * np.pi * np.array([ks[0].norm, ks[1].norm]))
    return Components((proj_px @ np.linalg.inv(M)) * mm_per_px, None, None)  # (M^T)^{-1} p in row-vector form


@dataclass(frozen=True)
class A1Map:
    """What maps the phases to the outputs, for the uncertainty (:func:`~glassdist.analyzer.uncertainty.field_uncertainty`).

    Attributes
    ----------
    T : ndarray (2, 2)
        mm per rad, component frame.
    W : ndarray (..., 2, 2)
        px per mm.
    R : ndarray (2, 2) or None
        Component frame -> camera frame (None: the components are the camera frame's).
    blur : ndarray (2, 2, 2) or None
        px^2 per component, compensated by the metric smoothing (None: not compensated).
    """

    T: np.ndarray
    W: np.ndarray
    R: np.ndarray | None
    blur: np.ndarray | None


@dataclass(frozen=True)
class ChannelEvaluation:
    """A1-A3 on the analysis grid: the camera-frame displacement (mm), the channels and the :class:`A1Map`."""

    delta_cam: np.ndarray
    channels: Channels
    a1: A1Map


def channels(ag: AnalysisGrid, comp: Components, ks: tuple[F.Carrier, F.Carrier], p: AnalyzerParams, p_c: float,
             mm_per_px: float, sigma_mm: float, distance_m: float) -> ChannelEvaluation:
    """A1-A3: displacement in backdrop mm (camera frame) and the channels, on the analysis grid."""
    delta, J = comp.delta_mm, comp.jacobian
    if J is not None:
        R = comp.frame_rotation
        assert R is not None
        ch = evaluate_displacement(delta, ag.valid, distance_m=distance_m, mm_per_px=mm_per_px,
                                   detrend_degree=p.detrend_degree, sigma_mm=sigma_mm, labels=ag.labels,
                                   step_px=ag.grid.step, report_mask=ag.report, jacobian=J, transfer=ag.transfer,
                                   frame_rotation=R)
        a1 = A1Map(p_c / (2 * np.pi) * np.eye(2), inverse_2x2(J), R,
                   None if ag.transfer is None else ag.transfer.gaussian_px2)
        return ChannelEvaluation(delta @ R, ch, a1)
    M = np.array([ks[0].f / ks[0].norm, ks[1].f / ks[1].norm]).T
    tr = ag.transfer
    iso_blur = None
    if tr is not None:  # camera-frame components mix both carriers: their mean blur, isotropic
        g = tr.gaussian_px2
        iso_blur = np.repeat((np.trace(g, axis1=1, axis2=2).mean() / 2 * np.eye(2))[None], 2, 0)
        tr = replace(tr, gaussian_px2=iso_blur)
    ch = evaluate_displacement(delta, ag.valid, distance_m=distance_m, mm_per_px=mm_per_px,
                               detrend_degree=p.detrend_degree, sigma_mm=sigma_mm, labels=ag.labels,
                               step_px=ag.grid.step, report_mask=ag.report, transfer=tr)
    T = mm_per_px * np.linalg.inv(M).T / (2 * np.pi * np.array([ks[0].norm, ks[1].norm]))[None, :]
    return ChannelEvaluation(delta, ch, A1Map(T, np.eye(2) / mm_per_px, None, iso_blur))
