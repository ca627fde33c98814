"""Deformation terms of the glass faces: analytic height, gradient and Hessian.

Every term is a smooth (or piecewise smooth) function of the pane-local in-plane
coordinates ``(u, v)`` in mm, returning a height ``h`` in mm along the pane
normal ``w`` (positive towards the backdrop). A face is the sum of its terms, so
the face positions are

.. math::

   w_{front}(u, v) = -d/2 + h_{front}(u, v), \\qquad w_{back}(u, v) = +d/2 + h_{back}(u, v).

All functions broadcast over arrays of ``u`` and ``v``. ``gradient`` returns
``(h_u, h_v)`` (dimensionless slopes) and ``hessian`` returns
``(h_uu, h_uv, h_vv)`` (1/mm).

References
----------
Paper §2.1 (roller waves from tempering, pillowing from IGU pressure).
"""

from __future__ import annotations

import math
from typing import Annotated, Literal, Union

import numpy as np
from pydantic import BaseModel, Field, model_validator

from ..validation import MODEL_CONFIG, Angle_deg, Length_mm, PositiveLength_mm

__all__ = [
    "Harmonic",
    "RollerWave",
    "Pillow",
    "SphericalCap",
    "GaussianBump",
    "PolynomialBump",
    "Plane",
    "EdgeLift",
    "Term",
    "FaceShape",
]

_FROZEN = MODEL_CONFIG
#: a slope of a plane term (dimensionless, at most 45 deg)
Slope = Annotated[float, Field(ge=-1, le=1)]


class _TermBase(BaseModel):
    """One term of a face's shape: height in mm over the face coordinates ``(u, v)`` in mm.

    Every term implements the four methods below, on arrays of any (broadcast) shape; the
    tracer's Newton step calls them at every iteration.
    """

    model_config = _FROZEN

    def height(self, u, v):  # pragma: no cover - abstract
        """The term's height ``h(u, v)``, mm."""
        raise NotImplementedError

    def gradient(self, u, v):  # pragma: no cover - abstract
        """``(h_u, h_v)``: the height's slope along ``u`` and ``v`` (dimensionless)."""
        raise NotImplementedError

    def hessian(self, u, v):  # pragma: no cover - abstract
        """``(h_uu, h_uv, h_vv)``: the height's second derivatives, 1/mm."""
        raise NotImplementedError

    def height_gradient(self, u, v):
        """``(h, h_u, h_v)`` in one call (terms override it to share work)."""
        return (self.height(u, v), *self.gradient(u, v))


class Harmonic(BaseModel):
    """Higher harmonic ``order * k`` of a roller wave (amplitude in mm, phase in degrees)."""

    model_config = _FROZEN
    order: int = Field(ge=2, le=32)
    amplitude_mm: Length_mm
    phase_deg: Angle_deg = 0.0


class RollerWave(_TermBase):
    """Roller wave from tempering: a 1-D sinusoid with optional harmonics.

    .. math::

       h(u, v) = \\sum_m A_m \\sin(m\\,k\\,\\xi + \\varphi_m), \\qquad
       \\xi = u\\cos\\theta + v\\sin\\theta, \\quad k = 2\\pi/\\Lambda,

    with ``m = 1`` the fundamental (``amplitude_mm``, ``phase_deg``) and the
    ``harmonics`` list adding orders ``m >= 2``. ``direction_deg`` is the angle
    ``theta`` of the wave vector from the pane's ``u`` axis towards ``v``.
    """

    kind: Literal["roller_wave"]
    amplitude_mm: Length_mm
    wavelength_mm: PositiveLength_mm
    direction_deg: Angle_deg = 0.0
    phase_deg: Angle_deg = 0.0
    harmonics: tuple[Harmonic, ...] = ()

    def _modes(self):
        k = 2 * math.pi / self.wavelength_mm
        yield k, self.amplitude_mm, math.radians(self.phase_deg)
        for h in self.harmonics:
            yield h.order * k, h.amplitude_mm, math.radians(h.phase_deg)

    def _xi(self, u, v):
        t = math.radians(self.direction_deg)
        return np.cos(t) * u + np.sin(t) * v, math.cos(t), math.sin(t)

    def height(self, u, v):
        xi, _, _ = self._xi(u, v)
        return sum(a * np.sin(k * xi + p) for k, a, p in self._modes())

    def gradient(self, u, v):
        xi, c, s = self._xi(u, v)
        d1 = sum(a * k * np.cos(k * xi + p) for k, a, p in self._modes())
        return c * d1, s * d1

    def hessian(self, u, v):
        xi, c, s = self._xi(u, v)
        d2 = sum(-a * k * k * np.sin(k * xi + p) for k, a, p in self._modes())
        return c * c * d2, c * s * d2, s * s * d2

    def height_gradient(self, u, v):
        xi, c, s = self._xi(u, v)
        h = d1 = 0.0
        for k, a, p in self._modes():
            ph = k * xi + p
            h = h + a * np.sin(ph)
            d1 = d1 + (a * k) * np.cos(ph)
        return h, c * d1, s * d1


class Pillow(_TermBase):
    """Pillowing dome (IGU pressure): a separable cosine dome over a rectangle.

    .. math::

       h = A \\cos(\\pi \\Delta u / a) \\cos(\\pi \\Delta v / b) \\quad
       (|\\Delta u| < a/2,\\ |\\Delta v| < b/2), \\qquad 0 \\text{ outside},

    with ``(a, b) = size_mm`` (the lowest plate mode; usually the pane size) and
    ``(\\Delta u, \\Delta v)`` measured from ``center_mm``. ``amplitude_mm > 0``
    bulges towards the backdrop.
    """

    kind: Literal["pillow"]
    amplitude_mm: Length_mm
    size_mm: tuple[Length_mm, Length_mm]
    center_mm: tuple[Length_mm, Length_mm] = (0.0, 0.0)

    @model_validator(mode="after")
    def _positive(self):
        if min(self.size_mm) <= 0:
            raise ValueError("size_mm must be positive")
        return self

    def _parts(self, u, v):
        a, b = self.size_mm
        du, dv = u - self.center_mm[0], v - self.center_mm[1]
        inside = (np.abs(du) < a / 2) & (np.abs(dv) < b / 2)
        ka, kb = math.pi / a, math.pi / b
        return inside, ka, kb, ka * du, kb * dv

    def height(self, u, v):
        inside, _, _, x, y = self._parts(u, v)
        return np.where(inside, self.amplitude_mm * np.cos(x) * np.cos(y), 0.0)

    def gradient(self, u, v):
        inside, ka, kb, x, y = self._parts(u, v)
        A = self.amplitude_mm
        return (
            np.where(inside, -A * ka * np.sin(x) * np.cos(y), 0.0),
            np.where(inside, -A * kb * np.cos(x) * np.sin(y), 0.0),
        )

    def height_gradient(self, u, v):
        # One set of sines and cosines for the three (the tracer's Newton step asks for all of
        # them at every iteration); the same products in the same order, so the same values.
        # A view inside the dome (the usual case: the dome is the pane) skips the masking.
        inside, ka, kb, x, y = self._parts(u, v)
        A = self.amplitude_mm
        cx, cy, sx, sy = np.cos(x), np.cos(y), np.sin(x), np.sin(y)
        out = (A * cx * cy, -A * ka * sx * cy, -A * kb * cx * sy)
        if np.all(inside):
            return tuple(np.asarray(o, dtype=float) for o in out)
        return tuple(np.where(inside, o, 0.0) for o in out)

    def hessian(self, u, v):
        inside, ka, kb, x, y = self._parts(u, v)
        A = self.amplitude_mm
        return (
            np.where(inside, -A * ka * ka * np.cos(x) * np.cos(y), 0.0),
            np.where(inside, A * ka * kb * np.sin(x) * np.sin(y), 0.0),
            np.where(inside, -A * kb * kb * np.cos(x) * np.cos(y), 0.0),
        )


class SphericalCap(_TermBase):
    """Spherical cap of a lens region (thickness variation), zero outside its aperture.

    .. math::

       h(\\rho) = \\operatorname{sign}(R)\\left(\\sqrt{R^2 - \\rho^2} - \\sqrt{R^2 - a^2}\\right)
       \\quad (\\rho < a), \\qquad 0 \\text{ outside},

    with ``R = radius_mm`` (signed) and ``a = aperture_mm``. ``R > 0`` bulges
    towards the backdrop, ``R < 0`` towards the camera. A biconvex lens is a cap
    with ``R < 0`` on the front face and ``R > 0`` on the back face; its thin-lens
    power is :math:`P = (n - 1)(2/|R|)` (Hecht 2017, §5.2).
    """

    kind: Literal["spherical_cap"]
    radius_mm: Length_mm
    aperture_mm: PositiveLength_mm
    center_mm: tuple[Length_mm, Length_mm] = (0.0, 0.0)

    @model_validator(mode="after")
    def _radius(self):
        if abs(self.radius_mm) <= self.aperture_mm:
            raise ValueError("|radius_mm| must exceed aperture_mm")
        return self

    def _parts(self, u, v):
        du, dv = u - self.center_mm[0], v - self.center_mm[1]
        r2 = du * du + dv * dv
        inside = r2 < self.aperture_mm**2
        R = abs(self.radius_mm)
        root = np.sqrt(np.maximum(R * R - r2, 1e-300))
        return inside, du, dv, root, math.copysign(1.0, self.radius_mm)

    def height(self, u, v):
        inside, _, _, root, sg = self._parts(u, v)
        R, a = abs(self.radius_mm), self.aperture_mm
        return np.where(inside, sg * (root - math.sqrt(R * R - a * a)), 0.0)

    def gradient(self, u, v):
        inside, du, dv, root, sg = self._parts(u, v)
        return np.where(inside, -sg * du / root, 0.0), np.where(inside, -sg * dv / root, 0.0)

    def height_gradient(self, u, v):
        inside, du, dv, root, sg = self._parts(u, v)
        R, a = abs(self.radius_mm), self.aperture_mm
        return (np.where(inside, sg * (root - math.sqrt(R * R - a * a)), 0.0),
                np.where(inside, -sg * du / root, 0.0), np.where(inside, -sg * dv / root, 0.0))

    def hessian(self, u, v):
        inside, du, dv, root, sg = self._parts(u, v)
        r3 = root**3
        R2 = self.radius_mm**2
        return (
            np.where(inside, -sg * (R2 - dv * dv) / r3, 0.0),
            np.where(inside, -sg * du * dv / r3, 0.0),
            np.where(inside, -sg * (R2 - du * du) / r3, 0.0),
        )


class GaussianBump(_TermBase):
    """Localised Gaussian defect: :math:`h = A\\exp(-\\rho^2 / 2s^2)`, ``s = sigma_mm``."""

    kind: Literal["gaussian"]
    amplitude_mm: Length_mm
    sigma_mm: PositiveLength_mm
    center_mm: tuple[Length_mm, Length_mm] = (0.0, 0.0)

    def _parts(self, u, v):
        du, dv = u - self.center_mm[0], v - self.center_mm[1]
        s2 = self.sigma_mm**2
        g = self.amplitude_mm * np.exp(-(du * du + dv * dv) / (2 * s2))
        return du, dv, s2, g

    def height(self, u, v):
        return self._parts(u, v)[3]

    def gradient(self, u, v):
        du, dv, s2, g = self._parts(u, v)
        return -du / s2 * g, -dv / s2 * g

    def height_gradient(self, u, v):
        du, dv, s2, g = self._parts(u, v)
        return g, -du / s2 * g, -dv / s2 * g

    def hessian(self, u, v):
        du, dv, s2, g = self._parts(u, v)
        return (du * du / s2 - 1) / s2 * g, du * dv / (s2 * s2) * g, (dv * dv / s2 - 1) / s2 * g


class PolynomialBump(_TermBase):
    """Lens of compact support: :math:`h = A\\,q^m`, :math:`q = 1 - \\rho^2/R^2` inside ``R``, 0 outside.

    .. math::

       h_u = -\\frac{2 m A}{R^2} q^{m-1} \\delta u, \\qquad
       h_{uv} = \\frac{4 m (m - 1) A}{R^4} q^{m-2} \\delta u\\,\\delta v
       - \\frac{2 m A}{R^2} q^{m-1} \\delta_{uv},

    with ``A = amplitude_mm``, ``R = radius_mm``, ``m = order`` (``m - 1`` continuous
    derivatives at the rim: the glass around it is flat). On both faces with opposite
    signs (front ``-A``, back ``+A``) it thickens the pane by ``2 A q^m``: a converging
    lens of thin-lens power :math:`(n - 1)\\,4 m A / R^2` (1/mm) at its centre.
    """

    kind: Literal["bump"]
    amplitude_mm: Length_mm
    radius_mm: PositiveLength_mm
    order: int = Field(default=3, ge=2, le=8)
    center_mm: tuple[Length_mm, Length_mm] = (0.0, 0.0)

    def _parts(self, u, v):
        du, dv = u - self.center_mm[0], v - self.center_mm[1]
        R2 = self.radius_mm**2
        q = np.maximum(1.0 - (du * du + dv * dv) / R2, 0.0)
        return du, dv, R2, q

    def height(self, u, v):
        return self.amplitude_mm * self._parts(u, v)[3] ** self.order

    def gradient(self, u, v):
        du, dv, R2, q = self._parts(u, v)
        c = -2.0 * self.order * self.amplitude_mm / R2 * q ** (self.order - 1)
        return c * du, c * dv

    def height_gradient(self, u, v):
        du, dv, R2, q = self._parts(u, v)
        c = -2.0 * self.order * self.amplitude_mm / R2 * q ** (self.order - 1)
        return self.amplitude_mm * q**self.order, c * du, c * dv

    def hessian(self, u, v):
        du, dv, R2, q = self._parts(u, v)
        m, A = self.order, self.amplitude_mm
        c1 = -2.0 * m * A / R2 * q ** (m - 1)
        c2 = np.where(q > 0, 4.0 * m * (m - 1) * A / (R2 * R2) * q ** (m - 2), 0.0)
        return c2 * du * du + c1, c2 * du * dv, c2 * dv * dv + c1


class Plane(_TermBase):
    """Plane / wedge: :math:`h = h_0 + s_u u + s_v v` (slopes dimensionless).

    On one face only it makes a wedge (thin prism); on both faces a tilt.
    """

    kind: Literal["plane"]
    slope: tuple[Slope, Slope] = (0.0, 0.0)
    offset_mm: Length_mm = 0.0

    def height(self, u, v):
        return self.offset_mm + self.slope[0] * u + self.slope[1] * v

    def gradient(self, u, v):
        z = np.zeros(np.broadcast(u, v).shape)
        return z + self.slope[0], z + self.slope[1]

    def hessian(self, u, v):
        z = np.zeros(np.broadcast(u, v).shape)
        return z, z.copy(), z.copy()


_EDGES = ("left", "right", "top", "bottom")


class EdgeLift(_TermBase):
    """Edge lift of a toughened pane: a quadratic rise within ``width_mm`` of each named edge.

    .. math::

       h(u, v) = \\sum_e A \\left(1 - \\frac{d_e}{w}\\right)^2 \\quad (d_e < w), \\qquad
       d_{left} = \\Delta u + a/2, \\; d_{right} = a/2 - \\Delta u, \\;
       d_{top} = \\Delta v + b/2, \\; d_{bottom} = b/2 - \\Delta v,

    ``A = height_mm`` at the edge (``> 0``: towards the backdrop, away from the camera), ``w =
    width_mm``, ``(a, b) = size_mm`` the rectangle whose edges lift (usually the pane) centred on
    ``center_mm``, ``(\\Delta u, \\Delta v)`` from it; ``top`` is the edge at the smaller ``v``
    (the image's top row, ``y`` down). ``d_e`` is clipped to ``[0, w]``: the height is ``A``
    beyond an edge, zero further than ``w`` in, with a continuous slope (zero at ``d = w``) and a
    curvature ``2 A / w^2`` within ``w``. Corners add the two edges' lifts. EN 12150-1:2015 § 6
    measures this lift with a straight edge resting on the flat part of the pane.
    """

    kind: Literal["edge_lift"]
    height_mm: Length_mm
    width_mm: PositiveLength_mm
    size_mm: tuple[Length_mm, Length_mm]
    center_mm: tuple[Length_mm, Length_mm] = (0.0, 0.0)
    edges: tuple[Literal["left", "right", "top", "bottom"], ...] = _EDGES

    @model_validator(mode="after")
    def _positive(self):
        if min(self.size_mm) <= 0:
            raise ValueError("size_mm must be positive")
        if len(set(self.edges)) != len(self.edges):
            raise ValueError("edges must not repeat")
        return self

    def _edges(self, u, v):
        """Per edge: ``(q, du/dd, dv/dd, inside)``, ``q = 1 - d / w`` clipped to [0, 1], ``inside``: ``0 <= d < w``."""
        a, b = self.size_mm
        du, dv = u - self.center_mm[0], v - self.center_mm[1]
        for e in self.edges:
            d, su, sv = {"left": (du + a / 2, 1.0, 0.0), "right": (a / 2 - du, -1.0, 0.0),
                         "top": (dv + b / 2, 0.0, 1.0), "bottom": (b / 2 - dv, 0.0, -1.0)}[e]
            q = 1.0 - np.asarray(d, float) / self.width_mm
            yield np.clip(q, 0.0, 1.0), su, sv, (q > 0) & (q <= 1)

    def height_gradient(self, u, v):
        A, w = self.height_mm, self.width_mm
        shape = np.broadcast(u, v).shape
        h, gu, gv = np.zeros(shape), np.zeros(shape), np.zeros(shape)
        for q, su, sv, inside in self._edges(u, v):
            h = h + A * q * q
            dh_dd = np.where(inside, -2.0 * A / w * q, 0.0)  # flat beyond the edge and further than w in
            gu, gv = gu + su * dh_dd, gv + sv * dh_dd
        return h, gu, gv

    def height(self, u, v):
        return self.height_gradient(u, v)[0]

    def gradient(self, u, v):
        return self.height_gradient(u, v)[1:]

    def hessian(self, u, v):
        A, w = self.height_mm, self.width_mm
        shape = np.broadcast(u, v).shape
        huu, huv, hvv = np.zeros(shape), np.zeros(shape), np.zeros(shape)
        for _, su, sv, inside in self._edges(u, v):
            c = np.where(inside, 2.0 * A / (w * w), 0.0)
            huu, hvv = huu + su * su * c, hvv + sv * sv * c
        return huu, huv, hvv


Term = Annotated[
    Union[RollerWave, Pillow, SphericalCap, GaussianBump, PolynomialBump, Plane, EdgeLift], Field(discriminator="kind")
]


class FaceShape:
    """Sum of deformation terms: the height field of one face (mm, along +w)."""

    def __init__(self, terms):
        self.terms = tuple(terms)

    def __bool__(self) -> bool:
        return bool(self.terms)

    def height(self, u, v):
        """Height, mm; shape of ``broadcast(u, v)``."""
        out = np.zeros(np.broadcast(u, v).shape)
        for t in self.terms:
            out = out + t.height(u, v)
        return out

    def gradient(self, u, v):
        """``(h_u, h_v)``, dimensionless."""
        gu = np.zeros(np.broadcast(u, v).shape)
        gv = gu.copy()
        for t in self.terms:
            a, b = t.gradient(u, v)
            gu = gu + a
            gv = gv + b
        return gu, gv

    def height_gradient(self, u, v):
        """``(h, h_u, h_v)``."""
        if len(self.terms) == 1:
            return self.terms[0].height_gradient(u, v)
        h = hu = hv = 0.0
        for t in self.terms:
            a, b, c = t.height_gradient(u, v)
            h, hu, hv = h + a, hu + b, hv + c
        return h, hu, hv

    def hessian(self, u, v):
        """``(h_uu, h_uv, h_vv)``, 1/mm."""
        out = [np.zeros(np.broadcast(u, v).shape) for _ in range(3)]
        for t in self.terms:
            out = [o + x for o, x in zip(out, t.hessian(u, v))]
        return tuple(out)
