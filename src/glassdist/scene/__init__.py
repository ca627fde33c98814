"""Glass distortion definition: pane, face deformations, backdrop, camera, imaging.

A scene is resolution-free: the faces are analytic height fields of the
pane-local coordinates in mm (with analytic gradients and Hessians), sampled by
whoever needs them (the ray tracer, the analytical model, another renderer).
Scene files are YAML or JSON; :func:`load_scene` validates them (unknown keys
are errors). Lengths are in mm, the glass-to-backdrop distance ``L`` in m.

Geometry (every engine must rebuild exactly this)
-------------------------------------------------
World frame
    Right-handed, ``x`` right, ``y`` down, ``z`` forward (from the camera
    towards the backdrop), in mm.
Camera
    Pinhole at ``camera.position_mm``; orientation ``R_cam = R_y(yaw) R_x(pitch)``
    with :math:`R_y(a) = [[\\cos a, 0, \\sin a], [0, 1, 0], [-\\sin a, 0, \\cos a]]`,
    :math:`R_x(b) = [[1, 0, 0], [0, \\cos b, -\\sin b], [0, \\sin b, \\cos b]]`: the
    columns of ``R_cam`` are the camera's right, down and optical axes; positive
    yaw looks right (+x), positive pitch looks up (-y); no roll. Focal length
    ``f``, sensor width ``s_w`` mapped on ``W`` columns (square pixels), principal
    point at the image centre. Pixel ``(row i, col j)`` is the square
    ``[j, j+1) x [i, i+1)``; its line of sight has camera-frame direction
    ``((j + 0.5 - W/2) p, (i + 0.5 - H/2) p, f)``, ``p = s_w / W``. With
    ``camera.distortion`` (Brown ``k1, k2, p1, p2``, OpenCV's convention) the
    point's normalised coordinates ``((j + 0.5 - W/2) p / f, (i + 0.5 - H/2) p / f)``
    are the *distorted* ones: the direction is ``(x, y, 1)`` with ``(x, y)`` their
    undistorted preimage (:meth:`glassdist.brown.BrownDistortion.undistort`).
Pane
    A slab of thickness ``d`` and refractive index ``n`` in air. Pane axes
    ``(u, v, w)`` are the columns of ``R_pane = R_y(pane.yaw) R_x(pane.pitch)``,
    origin at ``pane.center_mm``; ``w`` is the normal pointing to the backdrop.
    Faces: ``w = -d/2 + h_front(u, v)`` (towards the camera) and
    ``w = +d/2 + h_back(u, v)``, for ``|u| <= width/2``, ``|v| <= height/2``.
    ``deformation.both`` terms are added to both faces, ``front``/``back`` to one.
    An optional opaque ``frame`` band covers the outer ``width_mm`` of the pane
    (tested where a ray meets the front face). Rays whose front-face hit lies
    outside the pane go straight.
Backdrop
    The plane ``z = pane.center_z + 1000 L``, facing the camera; its coordinates
    are the world ``(X, Y)`` (so, for a camera without roll, ``X`` points to the
    image's right and ``Y`` to its bottom). The pattern is drawn in pattern
    coordinates ``Rot(-rotation_deg) (X - offset_mm)``.
Reflection (``viewing.mode: reflection``)
    The backdrop is a grid board on the camera's side, the plane
    ``z = pane.center_z - 1000 D`` (``D = backdrop.distance_m``) facing the pane; the lines
    of sight reflect off the front face (and, with ``viewing.back_face``, off the back face
    too, Fresnel-weighted) and land on it. The glass-less landing is the reflection in the
    flat plane of the nominal front face (a flat reference surface at the same place).
Displacement
    ``delta(pixel)`` = landing point of the pixel's line of sight on the
    backdrop with the glass minus without it, backdrop mm, ``[..., 0] = X``,
    ``[..., 1] = Y``.

References
----------
Paper §2 and §2.1 (Virtual Pipeline, glass distortion definition).
"""

from .geometry import (
    landing_jacobian,
    pattern_coordinates,
    pattern_intensity,
    pixel_directions,
    pixel_grid,
    straight_landing,
)
from .model import (
    Backdrop,
    Camera,
    Deformation,
    Frame,
    Imaging,
    LensDistortion,
    Lighting,
    Noise,
    Pane,
    RenderSettings,
    Scene,
    Viewing,
    load_scene,
    rotation_yaw_pitch,
    scene_from_dict,
)
from .surfaces import (
    EdgeLift,
    FaceShape,
    GaussianBump,
    Harmonic,
    Pillow,
    Plane,
    PolynomialBump,
    RollerWave,
    SphericalCap,
)

__all__ = [
    "Scene",
    "Pane",
    "Frame",
    "Deformation",
    "Backdrop",
    "Camera",
    "LensDistortion",
    "Imaging",
    "Noise",
    "Lighting",
    "RenderSettings",
    "Viewing",
    "load_scene",
    "scene_from_dict",
    "rotation_yaw_pitch",
    "RollerWave",
    "Harmonic",
    "Pillow",
    "SphericalCap",
    "GaussianBump",
    "PolynomialBump",
    "Plane",
    "EdgeLift",
    "FaceShape",
    "pixel_directions",
    "pixel_grid",
    "straight_landing",
    "landing_jacobian",
    "pattern_coordinates",
    "pattern_intensity",
]
