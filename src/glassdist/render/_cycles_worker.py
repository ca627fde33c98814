"""Render one glassdist Cycles job inside Blender's Python (``bpy``).

This script runs in a *separate* interpreter that has the ``bpy`` module (its
own NumPy, usually 1.26); it imports nothing from glassdist. It is started by
:mod:`glassdist.render.cycles` as::

    python _cycles_worker.py JOB.json

and communicates only through files and single-line messages on stdout:

``GLASSDIST-PROGRESS <phase> <done> <total>``
    progress; ``phase`` is ``setup`` (scene construction) or ``sample``
    (samples per pixel done out of the total).
``GLASSDIST-DONE <path of the .npy image>``
    the render finished and the image was written.
``GLASSDIST-ERROR <message>``
    the job could not be rendered (the exit status is then non-zero).

Job format (``format = "glassdist-cycles-job"``, ``version = 1``)
----------------------------------------------------------------
All lengths are in millimetres in the *job world frame*; the rotation
``world_to_blender`` (3x3, row-major, default identity) maps job-world
vectors to Blender world vectors, and the scene is built in metres
(``blender = 1e-3 * world_to_blender @ job``) so that it opens at its true
size in Blender.

``image``
    ``width``, ``height`` in pixels.
``camera``
    Pinhole camera. ``focal_mm``, ``sensor_width_mm`` (the sensor width
    spans ``width`` pixels; pixels are square); ``position_mm`` (3,);
    ``rotation`` (3x3, row-major) whose *columns* are the camera axes in the
    job world: x_cam (direction of increasing column), y_cam (direction of
    increasing row) and z_cam (optical axis, pointing into the scene);
    ``principal_point_px`` ``[x, y]``: principal point in pixel coordinates
    where the centre of pixel (row r, col c) is at (x, y) = (c, r); ``null``
    means the image centre ((W - 1) / 2, (H - 1) / 2).
``glass``
    A slab given by two height fields over a rectangular grid of the pane's
    local frame: local point ``(x, y, z)`` maps to the job world as
    ``origin_mm + axes @ (x, y, z)`` where ``axes`` (3x3, row-major, columns
    are the local axes, a proper rotation). The NPZ arrays ``glass_x`` (nx,),
    ``glass_y`` (ny,) hold the grid, ``front_z`` / ``back_z`` (ny, nx) the
    heights of the two faces (``back_z > front_z``; the front face is the one
    on the local -z side) and ``front_grad`` / ``back_grad`` (ny, nx, 2) their
    analytic gradients (dz/dx, dz/dy), used as smooth shading normals.
    ``ior`` is the refractive index; ``bsdf`` is ``"refraction"`` (no
    Fresnel reflection: every ray is transmitted), ``"glass"`` (Fresnel
    reflection and transmission, ghosts included) or ``"mirror"`` (the front
    face alone, a perfect mirror: the pane seen in reflection; ``back_z`` and
    ``back_grad`` are then unused); ``transmittance`` ``T``
    (default 1) is applied as ``sqrt(T)`` at each interface. ``frame``
    (optional): ``{"intensity", "inner_half_mm": [hu, hv], "lift_mm"}``, an
    opaque band emitting ``intensity`` over the front-face quads outside
    ``|x| <= hu, |y| <= hv``, lifted ``lift_mm`` towards the camera (the grid
    should have lines at ``x = +-hu`` and ``y = +-hv``).
``backdrop``
    An emitting rectangle: centre ``origin_mm``, unit in-plane axes ``u``,
    ``v`` (job world), ``size_mm`` ``[su, sv]``. Its radiance at plane
    coordinates (u, v) in mm (relative to the centre) is given by
    ``pattern``: ``{"kind": "lines", "pitch_mm", "line_width_mm",
    "rotation_deg", "offset_mm": [ou, ov], "line_value", "background_value"}``
    (two families of parallel lines, at angles ``rotation_deg`` and
    ``rotation_deg + 90`` from u, each line ``|s - k p| < w / 2`` with
    ``s`` the signed distance across the family measured from the offset),
    ``{"kind": "checkerboard", "pitch_mm", "rotation_deg", "offset_mm",
    "dark_value", "light_value"}``, or ``{"kind": "image", "extent_mm":
    [u0, u1, v0, v1]}`` with the NPZ array ``backdrop_image`` (rows, cols)
    sampled at cell centres, row 0 at v = v1 and column 0 at u = u0
    (bilinear interpolation). ``visible_to_camera`` (default true): false
    hides the backdrop from camera rays, for a board in the camera's plane
    seen only in the pane's reflection.
``render``
    ``samples`` (per pixel), ``seed`` (integer), ``threads`` (0 = all
    cores), ``max_bounces``, ``chunks``: the samples are rendered as this
    many consecutive subsets of one sample sequence (for progress reports;
    the mean of the subsets equals a single render of all samples).
``outputs``
    ``npy`` (required): float32 image (H, W), row 0 at the top, linear
    radiance (1.0 = a backdrop of value 1 seen directly); ``exr``: optional
    32-bit float EXR of the same render; ``blend``: optional ``.blend``
    file of the scene.
``arrays``
    Path of the NPZ holding the arrays named above.

Notes
-----
The render uses a box pixel filter of width 1 px (each pixel is the average
over its area), no denoiser, no adaptive sampling, no clamping and a fixed
sampling seed, so a job renders to the same image every time on the same
build. The EXR is written and read back in scene-linear values; no view
transform touches the returned array.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time

import numpy as np

JOB_FORMAT = "glassdist-cycles-job"
JOB_VERSION = 1
MM = 1e-3  # metres per millimetre (Blender scene unit is the metre)


def _say(*words) -> None:
    sys.stdout.write("GLASSDIST-" + " ".join(str(w) for w in words) + "\n")
    sys.stdout.flush()


def _mat3(values) -> np.ndarray:
    m = np.asarray(values, dtype=np.float64).reshape(3, 3)
    return m


# ----------------------------------------------------------------------------------------------
# geometry (pure NumPy, testable without bpy)
# ----------------------------------------------------------------------------------------------
def slab_mesh(x, y, front_z, back_z, front_grad, back_grad):
    """Closed quad mesh of a slab between two height fields, with per-corner normals.

    Parameters
    ----------
    x : ndarray, shape (nx,)
        Grid abscissae in the pane's local frame, mm, increasing.
    y : ndarray, shape (ny,)
        Grid ordinates, mm, increasing.
    front_z, back_z : ndarray, shape (ny, nx)
        Heights of the front (local -z side) and back faces, mm; ``back_z > front_z``.
    front_grad, back_grad : ndarray, shape (ny, nx, 2)
        Gradients (dz/dx, dz/dy) of the two faces (dimensionless).

    Returns
    -------
    verts : ndarray, shape (2 * ny * nx, 3)
        Vertices in the local frame, mm: front grid first, then back grid.
    quads : ndarray, shape (M, 4)
        Vertex indices of each quad, wound so that the geometric normal points
        out of the slab.
    corner_normals : ndarray, shape (M, 4, 3)
        Unit shading normal at each quad corner, pointing out of the slab:
        the analytic normals on the two faces, the flat wall normals on the rim.
    """
    front, front_quads, front_normals = face_mesh(x, y, front_z, front_grad)
    back, back_quads, _ = face_mesh(x, y, back_z, back_grad)
    ny, nx = len(y), len(x)
    verts = np.concatenate([front, back])
    nf = ny * nx
    n_back = _unit(np.stack([-back_grad[..., 0], -back_grad[..., 1], np.ones((ny, nx))], -1)).reshape(-1, 3)
    # the back face's outward normal is +z: the front face's winding reversed
    back_quads = back_quads[:, ::-1] + nf
    quads = [front_quads, back_quads]
    normals = [front_normals, n_back[back_quads - nf]]
    idx = np.arange(nf).reshape(ny, nx)

    # rim: walk the boundary counter-clockwise seen from +z
    ring = np.concatenate([idx[0, :-1], idx[:-1, -1], idx[-1, :0:-1], idx[:0:-1, 0]])
    p, q = ring, np.roll(ring, -1)
    # wall quad (front p, front q, back q, back p): outward for a counter-clockwise ring
    walls = np.stack([p, q, q + nf, p + nf], axis=1)
    edge = verts[q] - verts[p]
    n_wall = _unit(np.stack([edge[:, 1], -edge[:, 0], np.zeros(len(p))], axis=1))
    quads.append(walls)
    normals.append(np.repeat(n_wall[:, None, :], 4, axis=1))
    return verts, np.concatenate(quads), np.concatenate(normals)


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def face_mesh(x, y, z, grad):
    """Quad mesh of one height field seen from its local -z side (the front face, the mirror).

    Parameters
    ----------
    x, y : ndarray, shapes (nx,) and (ny,)
        The grid, as in :func:`slab_mesh`.
    z : ndarray, shape (ny, nx)
        Heights, mm.
    grad : ndarray, shape (ny, nx, 2)
        Gradients (dz/dx, dz/dy) (dimensionless).

    Returns
    -------
    verts : ndarray, shape (ny * nx, 3)
        Vertices in the local frame, mm.
    quads : ndarray, shape (M, 4)
        Vertex indices of each quad, wound so that the geometric normal points to -z.
    corner_normals : ndarray, shape (M, 4, 3)
        Unit analytic normal ``(gx, gy, -1) / |.|`` at each quad corner.
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    ny, nx = len(y), len(x)
    X, Y = np.meshgrid(x, y)
    verts = np.stack([X, Y, z], axis=-1).reshape(-1, 3)
    normal = _unit(np.stack([grad[..., 0], grad[..., 1], -np.ones((ny, nx))], -1)).reshape(-1, 3)
    idx = np.arange(ny * nx).reshape(ny, nx)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    # (a, b, c, d) runs counter-clockwise seen from +z, so (a, d, c, b) faces -z
    quads = np.stack([a, d, c, b], axis=1)
    return verts, quads, normal[quads]


def camera_pose_blender(rotation, position_mm, world_to_blender):
    """Blender ``matrix_world`` (4x4, metres) of a camera given in the job's convention.

    Blender cameras look along their local -Z with +Y up; the job's camera
    axes are x_cam (columns), y_cam (rows, down) and z_cam (forward).
    """
    r = world_to_blender @ _mat3(rotation)
    m = np.eye(4)
    m[:3, 0] = r[:, 0]
    m[:3, 1] = -r[:, 1]
    m[:3, 2] = -r[:, 2]
    m[:3, 3] = MM * (world_to_blender @ np.asarray(position_mm, dtype=np.float64))
    return m


# ----------------------------------------------------------------------------------------------
# bpy scene construction
# ----------------------------------------------------------------------------------------------
def _new_object(bpy, name, data, matrix):
    import mathutils

    obj = bpy.data.objects.new(name, data)
    bpy.context.scene.collection.objects.link(obj)
    obj.matrix_world = mathutils.Matrix([list(row) for row in matrix])
    return obj


def _build_mesh(bpy, name, verts_m, quads, corner_normals):
    mesh = bpy.data.meshes.new(name)
    nv, nq = len(verts_m), len(quads)
    mesh.vertices.add(nv)
    mesh.vertices.foreach_set("co", np.ascontiguousarray(verts_m, dtype=np.float32).ravel())
    mesh.loops.add(4 * nq)
    mesh.loops.foreach_set("vertex_index", np.ascontiguousarray(quads, dtype=np.int32).ravel())
    mesh.polygons.add(nq)
    mesh.polygons.foreach_set("loop_start", np.arange(0, 4 * nq, 4, dtype=np.int32))
    mesh.update(calc_edges=True)
    mesh.shade_smooth()
    if corner_normals is not None:
        mesh.normals_split_custom_set(np.ascontiguousarray(corner_normals, dtype=np.float32).reshape(-1, 3))
    return mesh


def _build_glass(bpy, job, arrays, world_to_blender):
    g = job["glass"]
    kind = g.get("bsdf", "refraction")
    if kind == "mirror":
        verts, quads, normals = face_mesh(arrays["glass_x"], arrays["glass_y"], arrays["front_z"], arrays["front_grad"])
    else:
        verts, quads, normals = slab_mesh(
            arrays["glass_x"], arrays["glass_y"], arrays["front_z"], arrays["back_z"],
            arrays["front_grad"], arrays["back_grad"],
        )
    axes = _mat3(g["axes"])
    if np.linalg.det(axes) < 0:
        raise ValueError("glass.axes must be a proper rotation (determinant +1)")
    origin = np.asarray(g["origin_mm"], dtype=np.float64)
    # place in the Blender world directly (vertex positions in metres), so the object is unscaled
    rot = world_to_blender @ axes
    verts_w = MM * ((verts @ rot.T) + world_to_blender @ origin)
    obj = _placed_object(bpy, "glass", verts_w, quads, normals @ rot.T)
    mat, nt, out = _new_material(bpy, "glass")
    if kind == "refraction":
        bsdf = nt.nodes.new("ShaderNodeBsdfRefraction")
    elif kind == "glass":
        bsdf = nt.nodes.new("ShaderNodeBsdfGlass")
    elif kind == "mirror":
        bsdf = nt.nodes.new("ShaderNodeBsdfGlossy")
    else:
        raise ValueError(f"glass.bsdf must be 'refraction', 'glass' or 'mirror', got {kind!r}")
    bsdf.distribution = "GGX"  # with roughness 0: a perfectly smooth (delta) interface
    if kind == "mirror":  # the board's radiance as seen in the mirror: reflectance 1
        bsdf.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    else:
        tau = math.sqrt(float(g.get("transmittance", 1.0)))  # two interfaces: T overall
        bsdf.inputs["Color"].default_value = (tau, tau, tau, 1.0)
        bsdf.inputs["IOR"].default_value = float(g["ior"])
    bsdf.inputs["Roughness"].default_value = 0.0
    nt.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    obj.data.materials.append(mat)
    if g.get("frame"):
        nfront = len(arrays["glass_x"]) * len(arrays["glass_y"])
        _build_frame(bpy, g["frame"], verts, quads, nfront, rot, world_to_blender @ origin)
    return obj


def _build_frame(bpy, frame, verts, quads, nfront, rot, origin_b):
    """Opaque emitting band over the front face (vertices ``< nfront``) outside ``|u| <= hu, |v| <= hv``."""
    hu, hv = (float(t) for t in frame["inner_half_mm"])
    front = quads[(quads < nfront).all(axis=1)]
    centre = verts[front].mean(axis=1)
    band = front[(np.abs(centre[:, 0]) > hu) | (np.abs(centre[:, 1]) > hv)]
    if len(band) == 0:
        return None
    used, inverse = np.unique(band, return_inverse=True)
    local = verts[used].copy()
    local[:, 2] -= float(frame.get("lift_mm", 0.01))  # towards the camera
    verts_w = MM * (local @ rot.T + origin_b)
    obj = _placed_object(bpy, "frame", verts_w, inverse.reshape(band.shape), None)
    mat, nt, out = _new_material(bpy, "frame")
    emit = nt.nodes.new("ShaderNodeEmission")
    val = float(frame["intensity"])
    emit.inputs["Color"].default_value = (val, val, val, 1.0)
    emit.inputs["Strength"].default_value = 1.0
    nt.links.new(emit.outputs["Emission"], out.inputs["Surface"])
    obj.data.materials.append(mat)
    return obj


def _placed_object(bpy, name, verts_w, faces, normals_w):
    """An unscaled object from vertices placed in the Blender world (m): its mesh is centred on the
    vertices' bounding box and the object moved there."""
    centre = 0.5 * (verts_w.min(axis=0) + verts_w.max(axis=0))
    mesh = _build_mesh(bpy, name, verts_w - centre, faces, normals_w)
    m = np.eye(4)
    m[:3, 3] = centre
    return _new_object(bpy, name, mesh, m)


def _new_material(bpy, name):
    """A material whose node tree holds only its output node: ``(material, node tree, output node)``."""
    mat = bpy.data.materials.new(name)
    nt = _node_tree(mat)
    nt.nodes.clear()
    return mat, nt, nt.nodes.new("ShaderNodeOutputMaterial")


def _node_tree(owner):
    """The shader node tree of a material or world (created on builds that still need it)."""
    if owner.node_tree is None:
        owner.use_nodes = True
    return owner.node_tree


def _math(nt, op, *inputs, label=None):
    """Add a Math node computing ``op(*inputs)``; inputs are sockets or numbers."""
    node = nt.nodes.new("ShaderNodeMath")
    node.operation = op
    if label:
        node.label = label
    for i, v in enumerate(inputs):
        if isinstance(v, (int, float)):
            node.inputs[i].default_value = float(v)
        else:
            nt.links.new(v, node.inputs[i])
    return node.outputs[0]


def _pattern_axes(nt, u, v, pat):
    """Sockets for the pattern coordinates of the two line families, in pitches.

    ``Rot(-rotation_deg) (X - offset_mm) / pitch_mm``: family 1 along (cos, sin), family 2 along
    (-sin, cos); ``scene.pattern_coordinates`` computes the same in NumPy.
    """
    p = float(pat["pitch_mm"])
    th = math.radians(float(pat.get("rotation_deg", 0.0)))
    ou, ov = (float(t) for t in pat.get("offset_mm", (0.0, 0.0)))
    u0 = _math(nt, "SUBTRACT", u, ou)
    v0 = _math(nt, "SUBTRACT", v, ov)
    cos, sin = math.cos(th), math.sin(th)
    return [
        _math(nt, "ADD", _math(nt, "MULTIPLY", u0, cu / p), _math(nt, "MULTIPLY", v0, cv / p))
        for cu, cv in ((cos, sin), (-sin, cos))
    ]


def _pattern_lines(nt, u, v, pat):
    """Sockets for a two-family line grid; returns the radiance socket."""
    half_width = 0.5 * float(pat["line_width_mm"]) / float(pat["pitch_mm"])  # in pitches
    in_line = []
    for s in _pattern_axes(nt, u, v, pat):
        frac = _math(nt, "FRACT", _math(nt, "ADD", s, 0.5))
        dist = _math(nt, "ABSOLUTE", _math(nt, "SUBTRACT", frac, 0.5))  # distance to the nearest line, 0..0.5
        in_line.append(_math(nt, "LESS_THAN", dist, half_width))
    mask = _math(nt, "MAXIMUM", in_line[0], in_line[1])
    lv, bv = float(pat.get("line_value", 0.0)), float(pat.get("background_value", 1.0))
    return _math(nt, "MULTIPLY_ADD", mask, lv - bv, bv)


def _pattern_checker(nt, u, v, pat):
    """Sockets for a checkerboard (cells one pitch wide); returns the radiance socket."""
    parity = [_math(nt, "FLOORED_MODULO", _math(nt, "FLOOR", s), 2.0) for s in _pattern_axes(nt, u, v, pat)]
    odd = _math(nt, "FLOORED_MODULO", _math(nt, "ADD", parity[0], parity[1]), 2.0)
    dv, lv = float(pat.get("dark_value", 0.0)), float(pat.get("light_value", 1.0))
    return _math(nt, "MULTIPLY_ADD", odd, dv - lv, lv)


def _pattern_image(bpy, nt, u, v, pat, image):
    u0, u1, v0, v1 = (float(t) for t in pat["extent_mm"])
    rows, cols = image.shape
    img = bpy.data.images.new("backdrop", width=cols, height=rows, alpha=False, float_buffer=True)
    img.colorspace_settings.name = "Non-Color"
    rgba = np.ones((rows, cols, 4), dtype=np.float32)
    rgba[..., :3] = np.asarray(image, dtype=np.float32)[::-1, :, None]  # Blender rows run bottom-up
    img.pixels.foreach_set(rgba.ravel())
    img.pack()
    # texture coordinates in [0, 1]: cell centres at (k + 0.5) / n
    s = _math(nt, "DIVIDE", _math(nt, "SUBTRACT", u, u0), u1 - u0)
    t = _math(nt, "DIVIDE", _math(nt, "SUBTRACT", v, v0), v1 - v0)
    comb = nt.nodes.new("ShaderNodeCombineXYZ")
    nt.links.new(s, comb.inputs[0])
    nt.links.new(t, comb.inputs[1])
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = img
    tex.interpolation = "Linear"
    tex.extension = "EXTEND"
    nt.links.new(comb.outputs[0], tex.inputs["Vector"])
    return tex.outputs["Color"]


def _build_backdrop(bpy, job, arrays, world_to_blender):
    b = job["backdrop"]
    u = np.asarray(b["u"], dtype=np.float64)
    v = np.asarray(b["v"], dtype=np.float64)
    u /= np.linalg.norm(u)
    v /= np.linalg.norm(v)
    nrm = np.cross(u, v)
    su, sv = (float(t) for t in b["size_mm"])
    # object frame: local x = u, y = v, z = u x v; local unit = 1 m, so local mm = 1000 * local
    m = np.eye(4)
    m[:3, 0] = world_to_blender @ u
    m[:3, 1] = world_to_blender @ v
    m[:3, 2] = world_to_blender @ nrm
    m[:3, 3] = MM * (world_to_blender @ np.asarray(b["origin_mm"], dtype=np.float64))
    hu, hv = 0.5 * su * MM, 0.5 * sv * MM
    verts = np.array([[-hu, -hv, 0], [hu, -hv, 0], [hu, hv, 0], [-hu, hv, 0]])
    mesh = _build_mesh(bpy, "backdrop", verts, np.array([[0, 1, 2, 3]]), None)
    obj = _new_object(bpy, "backdrop", mesh, m)
    obj.visible_camera = bool(b.get("visible_to_camera", True))

    mat, nt, out = _new_material(bpy, "backdrop")
    try:
        mat.emission_sampling = "NONE"  # reached only through specular paths: no light sampling
    except AttributeError:  # pragma: no cover - older builds
        pass
    coord = nt.nodes.new("ShaderNodeTexCoord")
    sep = nt.nodes.new("ShaderNodeSeparateXYZ")
    nt.links.new(coord.outputs["Object"], sep.inputs[0])
    uu = _math(nt, "MULTIPLY", sep.outputs[0], 1.0 / MM, label="u_mm")
    vv = _math(nt, "MULTIPLY", sep.outputs[1], 1.0 / MM, label="v_mm")
    pat = b["pattern"]
    kind = pat.get("kind")
    if kind == "lines":
        value = _pattern_lines(nt, uu, vv, pat)
    elif kind == "checkerboard":
        value = _pattern_checker(nt, uu, vv, pat)
    elif kind == "image":
        value = _pattern_image(bpy, nt, uu, vv, pat, arrays["backdrop_image"])
    else:
        raise ValueError(f"backdrop.pattern.kind must be 'lines', 'checkerboard' or 'image', got {kind!r}")
    emit = nt.nodes.new("ShaderNodeEmission")
    emit.inputs["Strength"].default_value = 1.0
    nt.links.new(value, emit.inputs["Color"])
    nt.links.new(emit.outputs["Emission"], out.inputs["Surface"])
    obj.data.materials.append(mat)
    return obj


def _build_camera(bpy, job, world_to_blender):
    c = job["camera"]
    w, h = int(job["image"]["width"]), int(job["image"]["height"])
    cam = bpy.data.cameras.new("camera")
    cam.type = "PERSP"
    cam.lens_unit = "MILLIMETERS"
    cam.lens = float(c["focal_mm"])
    cam.sensor_fit = "HORIZONTAL"
    cam.sensor_width = float(c["sensor_width_mm"])
    cam.sensor_height = float(c["sensor_width_mm"]) * h / w
    cam.clip_start = 1e-3
    cam.clip_end = 1e4
    pp = c.get("principal_point_px")
    if pp is not None:
        # Blender shifts are fractions of the larger image side; +shift_y moves the
        # principal point up, i.e. towards smaller row numbers
        side = float(max(w, h))
        cam.shift_x = (float(pp[0]) - 0.5 * (w - 1)) / side
        cam.shift_y = -(float(pp[1]) - 0.5 * (h - 1)) / side
    obj = _new_object(bpy, "camera", cam, camera_pose_blender(c["rotation"], c["position_mm"], world_to_blender))
    bpy.context.scene.camera = obj
    return obj


def _configure(bpy, job):
    scene = bpy.context.scene
    r = job["render"]
    scene.render.engine = "CYCLES"
    cy = scene.cycles
    cy.device = "CPU"
    cy.samples = int(r["samples"])
    cy.use_adaptive_sampling = False
    cy.use_denoising = False
    cy.seed = int(r.get("seed", 0)) % (2**31)
    cy.use_animated_seed = False
    cy.pixel_filter_type = "BOX"
    cy.filter_width = 1.0
    nb = int(r.get("max_bounces", 32))
    cy.max_bounces = nb
    cy.transmission_bounces = nb
    cy.glossy_bounces = nb
    cy.transparent_max_bounces = nb
    cy.diffuse_bounces = 0
    cy.volume_bounces = 0
    cy.sample_clamp_direct = 0.0
    cy.sample_clamp_indirect = 0.0
    cy.blur_glossy = 0.0
    cy.caustics_reflective = True
    cy.caustics_refractive = True
    scene.render.resolution_x = int(job["image"]["width"])
    scene.render.resolution_y = int(job["image"]["height"])
    scene.render.resolution_percentage = 100
    scene.render.pixel_aspect_x = 1.0
    scene.render.pixel_aspect_y = 1.0
    scene.render.film_transparent = False
    scene.render.use_compositing = False
    scene.render.use_sequencer = False
    threads = int(r.get("threads", 0))
    if threads > 0:
        scene.render.threads_mode = "FIXED"
        scene.render.threads = threads
    # the EXR holds scene-linear radiance whatever the view transform; "Standard" keeps a
    # viewer of the .blend from applying AgX's tone curve
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    world = bpy.data.worlds.new("black")
    bg = _node_tree(world).nodes.get("Background")
    if bg is not None:
        bg.inputs["Strength"].default_value = 0.0
        bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    else:
        world.color = (0.0, 0.0, 0.0)
    scene.world = world
    img = scene.render.image_settings
    img.file_format = "OPEN_EXR"
    img.color_depth = "32"
    img.color_mode = "RGB"
    img.exr_codec = "ZIP"


def _chunks(total, n):
    """Split ``total`` samples into ``n`` consecutive slices ``(offset, count)``."""
    n = max(1, min(int(n), total))
    edges = [round(i * total / n) for i in range(n + 1)]
    return [(a, b - a) for a, b in zip(edges[:-1], edges[1:])]


def _progress_handler(offset, total):
    """``render_stats`` handler turning Cycles' "Sample k/n" status into progress lines."""
    import re

    pattern = re.compile(r"Sample (\d+)/(\d+)")
    last = [-1]

    def handler(*args):
        text = " ".join(str(a) for a in args)  # the handler receives the status line
        m = pattern.search(text)
        if m:
            done = offset + int(m.group(1))
            if done != last[0]:
                last[0] = done
                _say("PROGRESS", "sample", done, total)

    return handler


def _write_exr(bpy, path, image):
    """Save a (H, W) float image as a 32-bit grey-in-RGB OpenEXR file (row 0 at the top)."""
    height, width = image.shape
    img = bpy.data.images.new("result", width=width, height=height, alpha=False, float_buffer=True)
    img.colorspace_settings.name = "Non-Color"
    rgba = np.ones((height, width, 4), dtype=np.float32)
    rgba[..., :3] = image[::-1, :, None]
    img.pixels.foreach_set(rgba.ravel())
    img.filepath_raw = path
    img.file_format = "OPEN_EXR"
    scene = bpy.context.scene
    img.save_render(path, scene=scene)
    bpy.data.images.remove(img)


def _read_exr(bpy, path, width, height):
    img = bpy.data.images.load(path, check_existing=False)
    img.colorspace_settings.name = "Non-Color"
    if (img.size[0], img.size[1]) != (width, height):
        raise RuntimeError(f"EXR has size {tuple(img.size)}, expected {(width, height)}")
    px = np.empty(width * height * img.channels, dtype=np.float32)
    img.pixels.foreach_get(px)
    px = px.reshape(height, width, img.channels)[::-1]  # Blender stores the bottom row first
    return np.ascontiguousarray(px[..., 0] if img.channels < 3 else px[..., :3].mean(axis=-1))


def run(job_path: str) -> str:
    """Render the job at ``job_path``; return the path of the written ``.npy`` image."""
    import bpy

    t0 = time.time()
    with open(job_path, encoding="utf-8") as f:
        job = json.load(f)
    if job.get("format") != JOB_FORMAT or int(job.get("version", -1)) != JOB_VERSION:
        raise ValueError(f"{job_path} is not a {JOB_FORMAT} version {JOB_VERSION} file")
    base = os.path.dirname(os.path.abspath(job_path))

    def resolve(p):
        return p if p is None or os.path.isabs(p) else os.path.join(base, p)

    arrays = dict(np.load(resolve(job["arrays"]))) if job.get("arrays") else {}
    w2b = _mat3(job.get("world_to_blender", np.eye(3).tolist()))

    _say("PROGRESS", "setup", 0, 1)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    _configure(bpy, job)
    if job.get("glass") is not None:
        _build_glass(bpy, job, arrays, w2b)
    _build_backdrop(bpy, job, arrays, w2b)
    _build_camera(bpy, job, w2b)
    _say("PROGRESS", "setup", 1, 1)

    outs = job["outputs"]
    blend = resolve(outs.get("blend"))
    if blend:
        bpy.ops.wm.save_as_mainfile(filepath=blend, check_existing=False, compress=True)

    scene = bpy.context.scene
    width, height = int(job["image"]["width"]), int(job["image"]["height"])
    total = int(job["render"]["samples"])
    chunks = _chunks(total, int(job["render"].get("chunks", 1)))
    # each chunk renders the next slice of the same sample sequence (a sample subset), so
    # their weighted mean equals one render of all samples (to float rounding). Persistent
    # data must stay off: with it, Cycles ignores the changed subset offset.
    scene.render.use_persistent_data = False
    part = os.path.join(base, "part.exr")
    scene.render.filepath = part
    acc = np.zeros((height, width), dtype=np.float64)
    scene.cycles.samples = total
    scene.cycles.use_sample_subset = len(chunks) > 1
    for offset, count in chunks:
        scene.cycles.sample_offset = offset
        scene.cycles.sample_subset_length = count
        handler = _progress_handler(offset, total)
        bpy.app.handlers.render_stats.append(handler)
        try:
            bpy.ops.render.render(write_still=True)
        finally:
            bpy.app.handlers.render_stats.remove(handler)
        if not os.path.exists(part):
            raise RuntimeError(f"Cycles wrote no image at {part}")
        acc += count * _read_exr(bpy, part, width, height)
        os.remove(part)
        _say("PROGRESS", "sample", offset + count, total)
    image = (acc / total).astype(np.float32)
    npy = resolve(outs["npy"])
    np.save(npy, image)
    exr = resolve(outs.get("exr"))
    if exr:
        _write_exr(bpy, exr, image)
    sys.stderr.write(f"rendered in {time.time() - t0:.1f} s\n")
    return npy


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        sys.stderr.write("usage: python _cycles_worker.py JOB.json\n")
        return 2
    try:
        npy = run(argv[0])
    except Exception as exc:  # noqa: BLE001 - reported to the parent process as one line
        import traceback

        traceback.print_exc(file=sys.stderr)
        _say("ERROR", f"{type(exc).__name__}: {exc}".replace("\n", " "))
        return 1
    _say("DONE", npy)
    return 0


if __name__ == "__main__":
    sys.exit(main())
