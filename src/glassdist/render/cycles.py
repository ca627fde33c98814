"""Blender Cycles render engine (the paper's renderer, §2.1), run in its own interpreter.

Cycles is used through the ``bpy`` module from PyPI (``bpy==5.0.1``, Python
3.11 only, about 1 GB installed). ``bpy`` pins its own NumPy (1.26), so it
never shares glassdist's environment: the engine writes the scene as a *job*
(a JSON file and an NPZ of sampled height fields), runs the self-contained
worker script :mod:`glassdist.render._cycles_worker` in the Cycles
interpreter as a subprocess, reads its progress from stdout and its image
back from an ``.npy`` file. Nothing here imports ``bpy``.

Finding the Cycles interpreter
------------------------------
1. ``$GLASSDIST_CYCLES_PYTHON``: any Python interpreter that can
   ``import bpy`` (for example a Blender-bundled Python, or a virtual
   environment of your own).
2. Otherwise the managed environment ``<cache>/cycles-venv``, where
   ``<cache>`` is ``$GLASSDIST_CACHE_DIR``, else ``$XDG_CACHE_HOME/glassdist``,
   else ``~/.cache/glassdist``. Create it once with ``glassdist cycles-setup`` (or
   ``python -m glassdist.render.cycles`` or ``bash scripts/install_cycles.sh``);
   it needs a ``python3.11`` interpreter and network access to PyPI (a 374 MB
   download).

Scene conversion
----------------
The job rebuilds exactly the geometry of :mod:`glassdist.scene`: world frame
x right, y down, z forward (mm); the pane as a closed mesh between the two
height fields sampled on a grid of at most ``spacing_mm`` (2 mm) with the
analytic normals as smooth shading normals, cropped to the part of the pane
the camera can see (plus a margin) and with grid lines on the pane and frame
edges; the frame band as an opaque emitter of ``frame.intensity`` just in
front of the front face; the backdrop as an emitting plane whose radiance is
the scene's line grid or checkerboard (``black``/``white`` values), written
as shader nodes so that its edges are exact; the camera as a Blender camera
with horizontal sensor fit, principal point at the image centre. In Blender
the scene is built in metres with Blender's Z up (world ``(x, y, z)`` maps to
Blender ``(x, z, -y)``), so a saved ``.blend`` opens upright at true size.

Light transport: a perfectly smooth dielectric of index ``n`` (``bsdf =
"glass"``, the default: Fresnel reflection and transmission with ghost
images; ``"refraction"``: every ray is transmitted, the exact engine's
photometry), with
the pane transmittance ``T`` applied as ``sqrt(T)`` per interface; box pixel
filter of 1 px, no denoiser, no adaptive sampling, fixed seed, black world.
The EXR is read back as scene-linear radiance (no view transform).

In reflection (``viewing.mode: reflection``) the pane is its front face alone,
a perfect mirror (``bsdf = "mirror"``, the exact engine's front-face
reflection), and the reference capture is the same mirror flat at the front
face's nominal plane; the board, in the camera's plane, is hidden from camera
rays and seen only in the pane. The back face's ghost (``viewing.back_face``)
is rendered by the exact engine only. The
scene's imaging effects (lighting, vignetting, blur, noise) are applied to
the Cycles image afterwards with the same code as the exact engine.

References
----------
Paper §2.1 (Blender Cycles, volumetric dielectric, n = 1.52).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Callable

import numpy as np

from ..errors import GlassdistError, InputError
from ..scene import Scene, pixel_directions, straight_landing
from ..validation import safe_text

__all__ = [
    "CyclesRenderer",
    "CyclesError",
    "BPY_REQUIREMENT",
    "cycles_python",
    "managed_env_dir",
    "find_cycles_python",
    "install_cycles",
    "write_job",
    "run_job",
    "register",
    "main",
]

log = logging.getLogger("glassdist.render.cycles")

BPY_REQUIREMENT = "bpy==5.0.1"
BPY_PYTHON = (3, 11)  # the only Python the bpy 5.0.1 wheels are built for
ENV_PYTHON = "GLASSDIST_CYCLES_PYTHON"
ENV_CACHE = "GLASSDIST_CACHE_DIR"
WORKER = Path(__file__).with_name("_cycles_worker.py")
INSTALL_HINT = ("run 'glassdist cycles-setup' once (downloads Blender's bpy, 374 MB) "
                "or set GLASSDIST_CYCLES_PYTHON to a Python that has bpy")

#: world (x right, y down, z forward) -> Blender (x right, y forward, z up); a proper rotation
WORLD_TO_BLENDER = ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, -1.0, 0.0))


class CyclesError(GlassdistError, RuntimeError):
    """The Cycles worker failed on a job that looked valid (the message names its log file)."""


# ----------------------------------------------------------------------------------------------
# the separate interpreter
# ----------------------------------------------------------------------------------------------
def managed_env_dir() -> Path:
    """Folder of the managed Cycles virtual environment (may not exist yet).

    ``$GLASSDIST_CACHE_DIR/cycles-venv`` if set, else
    ``$XDG_CACHE_HOME/glassdist/cycles-venv``, else ``~/.cache/glassdist/cycles-venv``.
    """
    if os.environ.get(ENV_CACHE):
        return Path(os.environ[ENV_CACHE]).expanduser() / "cycles-venv"
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base).expanduser() / "glassdist" / "cycles-venv"


def _venv_python(env: Path) -> Path:
    return env / ("Scripts/python.exe" if os.name == "nt" else "bin/python")


def cycles_python() -> Path:
    """The interpreter that would run Cycles: ``$GLASSDIST_CYCLES_PYTHON`` or the managed one."""
    explicit = os.environ.get(ENV_PYTHON)
    if explicit:
        return Path(explicit).expanduser()
    return _venv_python(managed_env_dir())


@lru_cache(maxsize=8)
def _bpy_version(python: str) -> str | None:
    """``bpy.app.version_string`` as seen by ``python``, or None if it cannot import bpy."""
    if not Path(python).exists():
        return None
    try:
        out = subprocess.run(
            [python, "-c", "import bpy; print(bpy.app.version_string)"],
            capture_output=True, text=True, timeout=300,
        )
    except (OSError, subprocess.TimeoutExpired):
        return None
    if out.returncode != 0:
        return None
    lines = out.stdout.strip().splitlines()
    return lines[-1] if lines else None


def find_cycles_python() -> Path:
    """Return an interpreter that can ``import bpy``.

    Raises
    ------
    InputError
        If neither ``$GLASSDIST_CYCLES_PYTHON`` nor the managed environment has
        ``bpy``; the message says how to install it.
    """
    py = cycles_python()
    if _bpy_version(str(py)) is None:
        where = f"{ENV_PYTHON}={py}" if os.environ.get(ENV_PYTHON) else f"{py}"
        raise InputError(f"the Cycles engine is not installed (no bpy at {where}); {INSTALL_HINT}")
    return py


def _find_base_python() -> str | None:
    """A Python 3.11 interpreter to create the managed environment from."""
    if sys.version_info[:2] == BPY_PYTHON:
        in_venv = sys.prefix != sys.base_prefix
        base = getattr(sys, "_base_executable", None) if in_venv else sys.executable
        if base and Path(base).is_file():
            return base
    return shutil.which(f"python{BPY_PYTHON[0]}.{BPY_PYTHON[1]}")


def install_cycles(
    *,
    env_dir: str | os.PathLike | None = None,
    base_python: str | None = None,
    quiet: bool = False,
) -> Path:
    """Create the managed Cycles environment (``python -m venv`` + ``pip install bpy==5.0.1``).

    Parameters
    ----------
    env_dir : path-like, optional
        Where to create it; default :func:`managed_env_dir`.
    base_python : str, optional
        A Python 3.11 interpreter to build the environment from; default
        ``python3.11`` on ``PATH`` (or this interpreter if it is 3.11).
    quiet : bool
        Hide pip's output.

    Returns
    -------
    Path
        The environment's interpreter (already able to ``import bpy``).

    Raises
    ------
    InputError
        No Python 3.11 is available, or pip could not install bpy (e.g. no
        network); the message says what to do.

    Notes
    -----
    Measured on a 2-core machine: about 45 s with a fast connection (374 MB
    download, about 1 GB installed). Concurrent installs are serialised by a
    lock file; an environment left half-made by an interrupted install (one
    that cannot ``import bpy``) is deleted and made again.
    """
    env = Path(env_dir) if env_dir is not None else managed_env_dir()
    py = _venv_python(env)
    if _bpy_version(str(py)) is not None:
        return py
    base = base_python or _find_base_python()
    if base is None:
        raise InputError(
            f"{BPY_REQUIREMENT} needs Python {BPY_PYTHON[0]}.{BPY_PYTHON[1]}, which was not found; "
            f"install python{BPY_PYTHON[0]}.{BPY_PYTHON[1]} or set {ENV_PYTHON} to a Python that has bpy"
        )
    env.parent.mkdir(parents=True, exist_ok=True)
    out = subprocess.DEVNULL if quiet else None
    with _file_lock(env.parent / (env.name + ".lock")):
        _bpy_version.cache_clear()
        if _bpy_version(str(py)) is not None:  # installed by someone else meanwhile
            return py
        if env.exists():
            shutil.rmtree(env)
        log.info("creating %s from %s", env, base)
        r = subprocess.run([base, "-m", "venv", str(env)], stdout=out, stderr=out)
        if r.returncode != 0:
            shutil.rmtree(env, ignore_errors=True)
            raise InputError(
                f"could not create a virtual environment with {base} (exit {r.returncode}); "
                "install the venv module of Python 3.11 (e.g. the python3.11-venv package)"
            )
        pip = [str(py), "-m", "pip", "install", "--disable-pip-version-check", "--progress-bar", "off", BPY_REQUIREMENT]
        r = subprocess.run(pip, stdout=out, stderr=out)
        if r.returncode != 0:
            shutil.rmtree(env, ignore_errors=True)
            raise InputError(
                f"pip could not install {BPY_REQUIREMENT} (exit {r.returncode}); check the network access to PyPI, "
                f"or set {ENV_PYTHON} to a Python that has bpy"
            )
        _bpy_version.cache_clear()
        if _bpy_version(str(py)) is None:
            raise InputError(
                f"{BPY_REQUIREMENT} was installed into {env} but 'import bpy' fails; "
                "see docs/user-guide/cycles.md for the system libraries it needs"
            )
    return py


class _file_lock:
    """Exclusive advisory lock on a file (POSIX ``flock``; a no-op where unavailable)."""

    def __init__(self, path: Path):
        self.path = path
        self.fd = None

    def __enter__(self):
        self.fd = os.open(self.path, os.O_CREAT | os.O_RDWR, 0o644)
        try:
            import fcntl

            fcntl.flock(self.fd, fcntl.LOCK_EX)
        except ImportError:  # pragma: no cover - non-POSIX
            pass
        return self

    def __exit__(self, *exc):
        os.close(self.fd)  # closing releases the lock
        return False


# ----------------------------------------------------------------------------------------------
# scene -> job
# ----------------------------------------------------------------------------------------------
_JOB_FORMAT = "glassdist-cycles-job"
_JOB_VERSION = 1
_FRAME_LIFT_MM = 0.01  # the frame band floats this far in front of the front face


def _axis_points(lo: float, hi: float, breaks, spacing: float) -> np.ndarray:
    """Grid points from ``lo`` to ``hi`` at most ``spacing`` apart, with every break point included."""
    knots = sorted({lo, hi, *(b for b in breaks if lo < b < hi)})
    parts = [np.linspace(a, b, max(1, math.ceil((b - a) / spacing - 1e-9)) + 1) for a, b in zip(knots[:-1], knots[1:])]
    return np.concatenate([parts[0]] + [p[1:] for p in parts[1:]])


def _visible_box(scene: Scene, margin_mm: float) -> tuple[float, float, float, float] | None:
    """Pane-local box ``(u0, u1, v0, v1)`` of the pane seen by the camera, mm, or None if unbounded.

    The image border rays (with a 2 px margin) are intersected with the two
    nominal face planes ``w = -d/2`` and ``w = +d/2``; the box of those points
    is widened by ``margin_mm``.
    """
    cam, pane = scene.camera, scene.pane
    H, W = cam.shape
    m = 2.0
    cols = np.array([-m, W + m, W + m, -m])
    rows = np.array([-m, -m, H + m, H + m])
    R = pane.rotation
    c = np.asarray(pane.center_mm, float)
    o = R.T @ (np.asarray(cam.position_mm, float) - c)
    dl = pixel_directions(cam, cols, rows) @ R
    if np.any(dl[:, 2] <= 1e-6):
        return None
    pts = []
    for w0 in (-pane.thickness_mm / 2, pane.thickness_mm / 2):
        t = (w0 - o[2]) / dl[:, 2]
        if np.any(t <= 0):
            return None
        pts.append(o[:2] + t[:, None] * dl[:, :2])
    pts = np.concatenate(pts)
    lo, hi = pts.min(axis=0) - margin_mm, pts.max(axis=0) + margin_mm
    return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])


def _glass_arrays(scene: Scene, spacing_mm: float, bsdf: str, *, flat: bool = False) -> tuple[dict, dict | None]:
    """Sampled faces of the (cropped) pane and the job's ``glass`` section; ``({}, None)`` if not in view.

    ``flat`` samples the undeformed faces (the flat reference mirror in reflection).
    """
    pane = scene.pane
    d = pane.thickness_mm
    hw, hh = pane.size_mm[0] / 2, pane.size_mm[1] / 2
    box = _visible_box(scene, margin_mm=d + 10.0 + 2 * spacing_mm)
    u0, u1, v0, v1 = -hw, hw, -hh, hh
    if box is not None:
        u0, u1, v0, v1 = max(u0, box[0]), min(u1, box[1]), max(v0, box[2]), min(v1, box[3])
        if u0 >= u1 or v0 >= v1:
            return {}, None
    fw = pane.frame.width_mm if pane.frame is not None else None
    ub = (-hw + fw, hw - fw) if fw else ()
    vb = (-hh + fw, hh - fw) if fw else ()
    u = _axis_points(u0, u1, ub, spacing_mm)
    v = _axis_points(v0, v1, vb, spacing_mm)
    if u.size * v.size > 20_000_000:
        raise InputError(
            f"the visible part of the pane needs {u.size} x {v.size} mesh vertices at {spacing_mm} mm; "
            "use a coarser spacing_mm or a smaller pane"
        )
    U, V = np.meshgrid(u, v)
    if flat:
        hf = fu = fv = hb = bu = bv = np.zeros(U.shape)
    else:
        hf, fu, fv = (np.broadcast_to(a, U.shape) for a in pane.deformation.front_shape.height_gradient(U, V))
        hb, bu, bv = (np.broadcast_to(a, U.shape) for a in pane.deformation.back_shape.height_gradient(U, V))
    front = -d / 2 + hf
    back = d / 2 + hb
    if np.any(back - front <= 0):
        raise InputError("the pane's deformed faces cross (thickness <= 0 somewhere); reduce the deformation amplitudes")
    arrays = {
        "glass_x": u,
        "glass_y": v,
        "front_z": front,
        "back_z": back,
        "front_grad": np.stack([fu, fv], axis=-1),
        "back_grad": np.stack([bu, bv], axis=-1),
    }
    section = {
        "ior": pane.refractive_index,
        "transmittance": pane.transmittance,
        "origin_mm": list(pane.center_mm),
        "axes": pane.rotation.tolist(),
        "frame": None if fw is None else {
            "intensity": pane.frame.intensity,
            "inner_half_mm": [hw - fw, hh - fw],
            "lift_mm": _FRAME_LIFT_MM,
        },
        "bsdf": bsdf,
    }
    return arrays, section


def _backdrop_section(scene: Scene) -> dict:
    """Job ``backdrop`` section: a plane at ``backdrop_z_mm`` far larger than the camera's view of it
    (in reflection, of its image in the pane)."""
    cam, b = scene.camera, scene.backdrop
    H, W = cam.shape
    cols = np.array([0.0, W, W, 0.0, W / 2])
    rows = np.array([0.0, 0.0, H, H, H / 2])
    pts = straight_landing(scene, pixel_directions(cam, cols, rows))
    centre = pts[4]
    half = np.abs(pts[:4] - centre).max(axis=0)
    size = 2 * (3 * half + 1000.0)  # generous: deflected rays must still land on it
    offset = [b.offset_mm[0] - centre[0], b.offset_mm[1] - centre[1]]
    if b.pattern == "lines":
        pattern = {
            "kind": "lines", "pitch_mm": b.pitch_mm, "line_width_mm": b.line_width_mm,
            "rotation_deg": b.rotation_deg, "offset_mm": offset,
            "line_value": b.black, "background_value": b.white,
        }
    elif b.pattern == "dots":
        raise ValueError("the Cycles renderer draws line grids and checkerboards only; "
                         "render a dot lattice with the exact tracer (glassdist.render.render)")
    else:
        pattern = {
            "kind": "checkerboard", "pitch_mm": b.pitch_mm, "rotation_deg": b.rotation_deg,
            "offset_mm": offset, "dark_value": b.black, "light_value": b.white,
        }
    return {
        "origin_mm": [float(centre[0]), float(centre[1]), scene.backdrop_z_mm],
        "u": [1.0, 0.0, 0.0],
        "v": [0.0, 1.0, 0.0],
        "size_mm": [float(size[0]), float(size[1])],
        "pattern": pattern,
        "visible_to_camera": not scene.reflection,  # a board in the camera's plane: seen in the pane only
    }


def _chunk_count(pixels: int, samples: int) -> int:
    """Number of sample slices a render is split into, for progress reports.

    Each slice re-synchronises the scene (about 0.5 s), so slices hold at least
    about 4 million pixel-samples (3 to 6 s on two cores), and at most 20.
    """
    return int(max(1, min(samples, 20, round(pixels * samples / 4e6))))


def _camera_section(scene: Scene) -> dict:
    """The job's ``camera`` section: pinhole, world-frame position and rotation (columns right, down, optical axis)."""
    cam = scene.camera
    if cam.distortion is not None:
        raise InputError("the Cycles engine renders a pinhole camera only; remove camera.distortion or use --engine exact")
    return {
        "focal_mm": cam.focal_length_mm,
        "sensor_width_mm": cam.sensor_width_mm,
        "position_mm": list(cam.position_mm),
        "rotation": cam.rotation.tolist(),
        "principal_point_px": None,
    }


def _render_section(scene: Scene, *, samples: int | None, seed: int, threads: int) -> dict:
    """The job's ``render`` section: samples per pixel (default the scene's), seed, threads, slices."""
    H, W = scene.camera.shape
    spp = int(samples if samples is not None else scene.render.samples_per_pixel)
    return {
        "samples": spp,
        "seed": int(seed) % (2**31),
        "threads": int(threads),
        "max_bounces": 32,
        "chunks": _chunk_count(W * H, spp),
    }


def write_job(
    scene: Scene,
    directory: str | os.PathLike,
    *,
    reference: bool = False,
    samples: int | None = None,
    seed: int = 0,
    spacing_mm: float = 2.0,
    bsdf: str = "glass",
    threads: int = 0,
    blend: str | os.PathLike | None = None,
    exr: str | os.PathLike | None = None,
) -> Path:
    """Write the Cycles job of a scene (``job.json`` + ``arrays.npz``) into ``directory``.

    Parameters
    ----------
    scene : Scene
        The glass distortion definition (see :mod:`glassdist.scene`).
    directory : path-like
        Existing folder; the worker also writes its image there.
    reference : bool
        Leave the pane out (the glass-less reference capture).
    samples : int, optional
        Samples per pixel; default ``scene.render.samples_per_pixel``.
    seed : int
        Cycles sampling seed (0 <= seed < 2**31).
    spacing_mm : float
        Largest vertex spacing of the pane mesh, mm (2 mm reproduces the analytic
        line positions to about 0.005 px on the paper's geometry).
    bsdf : {"glass", "refraction"}
        Fresnel glass (reflections, ghosts; the default) or refraction only
        (every ray transmitted, as in the exact engine). Unused in reflection,
        where the pane is its front face as a perfect mirror.
    threads : int
        CPU threads for Cycles, 0 for all.
    blend, exr : path-like, optional
        Also save the Blender scene / the 32-bit EXR render there.

    Returns
    -------
    Path
        The job file.
    """
    if bsdf not in ("refraction", "glass"):
        raise InputError(f"bsdf must be 'refraction' or 'glass', got '{bsdf}'")
    if not spacing_mm > 0:
        raise InputError(f"spacing_mm must be positive, got {spacing_mm}")
    if scene.reflection and scene.viewing.back_face:
        raise InputError("the cycles engine renders the front face's reflection only; render the back face's ghost "
                         "(viewing.back_face) with --engine exact")
    directory = Path(directory)
    if scene.reflection:  # the pane's front face as a mirror; the reference is that mirror flat, unframed
        arrays, glass = _glass_arrays(scene, spacing_mm, "mirror", flat=reference)
        if reference and glass is not None:
            glass = {**glass, "frame": None}  # as the exact engine's reference: the board alone
    else:
        arrays, glass = _glass_arrays(scene, spacing_mm, bsdf) if not reference else ({}, None)
    np.savez(directory / "arrays.npz", **(arrays or {"empty": np.zeros(1)}))
    H, W = scene.camera.shape
    job = {
        "format": _JOB_FORMAT,
        "version": _JOB_VERSION,
        "scene_name": scene.name,
        "world_to_blender": [list(r) for r in WORLD_TO_BLENDER],
        "image": {"width": W, "height": H},
        "camera": _camera_section(scene),
        "glass": glass,
        "backdrop": _backdrop_section(scene),
        "render": _render_section(scene, samples=samples, seed=seed, threads=threads),
        "outputs": {
            "npy": "render.npy",
            "exr": None if exr is None else str(Path(exr).resolve()),
            "blend": None if blend is None else str(Path(blend).resolve()),
        },
        "arrays": "arrays.npz",
    }
    path = directory / "job.json"
    path.write_text(json.dumps(job, indent=1) + "\n", encoding="utf-8")
    return path


# ----------------------------------------------------------------------------------------------
# running the worker
# ----------------------------------------------------------------------------------------------
def run_job(
    job_path: str | os.PathLike,
    *,
    python: str | os.PathLike | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> np.ndarray:
    """Run the Cycles worker on a job and return its image.

    Parameters
    ----------
    job_path : path-like
        ``job.json`` written by :func:`write_job`.
    python : path-like, optional
        Interpreter with ``bpy``; default :func:`find_cycles_python`.
    progress : callable, optional
        Called as ``progress(samples_done, samples_total)`` while Cycles samples.

    Returns
    -------
    ndarray, shape (H, W), float64
        Linear radiance, row 0 at the top.

    Raises
    ------
    CyclesError
        The worker failed; the message quotes its error and names its log file.
    """
    job_path = Path(job_path)
    py = Path(python) if python is not None else find_cycles_python()
    log_path = job_path.with_name("worker.log")
    # the worker runs from a copy next to the job, in isolated mode: this package's folder
    # (which holds a module named "cycles", like Blender's add-on) never lands on sys.path
    worker = job_path.with_name("glassdist_cycles_worker.py")
    shutil.copyfile(WORKER, worker)
    cmd = [str(py), "-I", str(worker), str(job_path)]
    log.debug("running %s", " ".join(cmd))
    t0 = time.perf_counter()
    done_path, error = None, None
    with open(log_path, "w", encoding="utf-8") as logf:
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=logf, text=True, bufsize=1)
        assert proc.stdout is not None
        for line in proc.stdout:
            if line.startswith("GLASSDIST-PROGRESS "):
                parts = line.split()
                if parts[1] == "sample" and progress is not None:
                    progress(int(parts[2]), int(parts[3]))
            elif line.startswith("GLASSDIST-DONE "):
                done_path = line[len("GLASSDIST-DONE "):].strip()
            elif line.startswith("GLASSDIST-ERROR "):
                error = line[len("GLASSDIST-ERROR "):].strip()
            else:
                logf.write(line)
        rc = proc.wait()
    if rc != 0 or done_path is None:
        why = error or f"the worker exited with status {rc}"
        raise CyclesError(f"Cycles render failed: {why}; see {log_path}")
    log.info("Cycles render took %.1f s", time.perf_counter() - t0)
    return np.load(done_path).astype(np.float64)


# ----------------------------------------------------------------------------------------------
# the engine
# ----------------------------------------------------------------------------------------------
@dataclass
class CyclesRenderer:
    """Blender Cycles path tracer behind the renderer protocol (see :mod:`glassdist.render`).

    Parameters
    ----------
    bsdf : {"glass", "refraction"}
        ``"glass"`` (default): Fresnel reflection and transmission at both
        faces, ghost images included, so the glass looks darker than in the
        exact engine (about 8 % at normal incidence) and is a little noisier;
        ``"refraction"`` transmits every ray (the exact engine's photometry).
    spacing_mm : float
        Largest vertex spacing of the pane mesh, mm.
    samples : int, optional
        Samples per pixel; default the scene's ``render.samples_per_pixel``.
    save_blend : path-like, optional
        Save the Blender scene of each distorted (not reference) render there.
    save_exr : path-like, optional
        Save the 32-bit EXR of each distorted render there.
    threads : int
        CPU threads for Cycles, 0 for all.
    python : path-like, optional
        Interpreter with ``bpy``; default :func:`find_cycles_python`.
    work_dir : path-like, optional
        Keep the job, image and worker log in this folder instead of a
        temporary one that is deleted.
    show_progress : bool, optional
        Show a progress bar on stderr when no ``progress`` callback is given;
        default: when stderr is a terminal.

    Notes
    -----
    The Cycles seed is drawn from the ``rng`` passed to :meth:`render`, so a
    seeded generator gives the same image on every run.
    """

    name = "cycles"

    bsdf: str = "glass"
    spacing_mm: float = 2.0
    samples: int | None = None
    save_blend: str | os.PathLike | None = None
    save_exr: str | os.PathLike | None = None
    threads: int = 0
    python: str | os.PathLike | None = None
    work_dir: str | os.PathLike | None = None
    show_progress: bool | None = None

    def render(
        self,
        scene: Scene,
        *,
        reference: bool,
        rng: np.random.Generator,
        progress: Callable[[int, int], None] | None = None,
    ) -> np.ndarray:
        """Render the distorted (``reference=False``) or glass-less image.

        Returns
        -------
        ndarray, shape (H, W), float64 in [0, 1]
            Linear intensity with the scene's imaging effects applied.

        Raises
        ------
        InputError
            Cycles is not installed (the message says how to install it), or the scene asks
            for the back face's ghost in reflection (rendered by the exact engine only).
        CyclesError
            The render failed.
        """
        py = Path(self.python) if self.python is not None else find_cycles_python()
        seed = int(rng.integers(0, 2**31 - 1))
        if self.work_dir is not None:
            work = Path(self.work_dir) / ("reference" if reference else "distorted")
            work.mkdir(parents=True, exist_ok=True)
            cleanup = False
        else:
            work = Path(tempfile.mkdtemp(prefix="glassdist-cycles-"))
            cleanup = True
        try:
            job = write_job(
                scene, work, reference=reference, samples=self.samples, seed=seed,
                spacing_mm=self.spacing_mm, bsdf=self.bsdf, threads=self.threads,
                blend=None if reference else self.save_blend,
                exr=None if reference else self.save_exr,
            )
            if progress is None and (self.show_progress or (self.show_progress is None and sys.stderr.isatty())):
                img = self._run_with_bar(job, py, "reference" if reference else "distorted")
            else:
                img = run_job(job, python=py, progress=progress)
        except CyclesError:
            cleanup = False  # keep the log for the error message
            raise
        finally:
            if cleanup:
                shutil.rmtree(work, ignore_errors=True)
        from .imaging import apply_imaging  # scipy.ndimage: not for `glassdist --help`

        return apply_imaging(np.clip(img, 0.0, None), scene.imaging, rng)

    @staticmethod
    def _run_with_bar(job: Path, py: Path, what: str) -> np.ndarray:
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        columns = (TextColumn(f"Cycles {what}"), BarColumn(), MofNCompleteColumn(), TextColumn("samples"), TimeElapsedColumn())
        with Progress(*columns, transient=True) as bar:
            task = bar.add_task("render", total=None)

            def update(done: int, total: int) -> None:
                bar.update(task, completed=done, total=total)

            return run_job(job, python=py, progress=update)


# ----------------------------------------------------------------------------------------------
# set-up command: `glassdist cycles-setup` / `python -m glassdist.render.cycles`
# ----------------------------------------------------------------------------------------------
def _check_base_python(python: str) -> str:
    """``python`` as an executable Python 3.11 interpreter (path), or a one-line InputError."""
    want = f"{BPY_PYTHON[0]}.{BPY_PYTHON[1]}"
    shown = safe_text(python)
    found = python if os.sep in python else (shutil.which(python) or python)
    if not Path(found).is_file():
        raise InputError(f"--python '{shown}' is not an interpreter file; give the path of a Python {want} interpreter")
    if not os.access(found, os.X_OK):
        raise InputError(f"--python '{shown}' is not executable; give the path of a Python {want} interpreter")
    try:
        r = subprocess.run([found, "-c", "import sys; print(*sys.version_info[:2])"], capture_output=True, text=True,
                           timeout=60)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise InputError(f"--python '{shown}' cannot be run ({safe_text(exc, 200)}); give a Python {want} interpreter") from None
    if r.returncode != 0 or r.stdout.split() != [str(BPY_PYTHON[0]), str(BPY_PYTHON[1])]:
        raise InputError(f"--python '{shown}' is not a Python {want} interpreter; bpy needs exactly Python {want}")
    return found


def _setup_main(args: argparse.Namespace) -> int:
    if args.python is not None:
        _check_base_python(args.python)
    if os.environ.get(ENV_PYTHON):
        py = find_cycles_python()
    else:
        py = install_cycles(base_python=args.python)
    version = _bpy_version(str(py))
    sys.stdout.write(f"Cycles ready: {py} (Blender {version})\n")
    return 0


def _add_setup_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--python", help="Python 3.11 interpreter to build the environment from (default: python3.11 on PATH)")


def register(subparsers) -> None:
    """Add the ``cycles-setup`` sub-command to the ``glassdist`` command line."""
    p = subparsers.add_parser(
        "cycles-setup",
        help="install the Blender Cycles engine (bpy) into its own environment",
        description=f"Create {managed_env_dir()} with {BPY_REQUIREMENT} (374 MB download, about 1 GB installed; "
        f"needs Python 3.11). Set {ENV_PYTHON} to use another interpreter that has bpy instead.",
    )
    _add_setup_arguments(p)
    p.set_defaults(func=_setup_main)


def main(argv=None) -> int:
    """``python -m glassdist.render.cycles``: install the Cycles engine."""
    p = argparse.ArgumentParser(prog="python -m glassdist.render.cycles", description="Install the Blender Cycles engine.",
                                allow_abbrev=False)
    _add_setup_arguments(p)
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    try:
        return _setup_main(args)
    except InputError as exc:
        sys.stderr.write(f"error: {exc}\n")
        return 2


if __name__ == "__main__":
    sys.exit(main())
