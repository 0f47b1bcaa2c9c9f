"""A run as a USD stage: one time-sampled mesh per body, the obstacles, the frame rate.

The stage (Pixar's ``usd-core``, module ``pxr``) has one ``Xform`` root ``/<scene>`` (its
default prim) holding

* ``/<scene>/<body>``: a ``UsdGeom.Mesh`` per body, named after the body
  (:func:`prim_names`): its boundary surface (:mod:`fem_anim.export.boundary`; a P2 body's
  refined through its edge dofs, each face split in four), triangles
  wound counter-clockwise seen from outside (``orientation = rightHanded``, no subdivision),
  ``points`` and ``extent`` sampled at every frame, and the primvars ``displacement``
  (|u| per vertex, m), ``energy_density`` (per face: the mean psi of the cell behind it,
  J/m^3; a shell's, per unit mid-surface area, J/m^2: the unit is in the primvar's
  ``documentation``) and ``body`` (the body number, constant). A shell (cloth) is its
  triangles themselves, wound as its mesh winds them, with ``doubleSided = true``: it has
  no inside, and a renderer must draw both its faces (Blender draws both sides of every
  mesh unless back-face culling is on);
* ``/<scene>/obstacles/<name>``: each static obstacle, a plane as a finite square quad (twice
  the bodies' extent over the run, about the projection of their centre) and a sphere as a
  ``UsdGeom.Sphere``.

Time: frame k (time t_k of the trajectory) is time code ``start_frame + t_k * fps``, with
``fps = 1 / (t_1 - t_0)`` the run's frame rate, written as ``timeCodesPerSecond`` and
``framesPerSecond``; ``startTimeCode`` and ``endTimeCode`` span the frames. Lengths are in
metres (``metersPerUnit = 1``); the up axis is the one gravity points against (Y or Z; Z
when there is no gravity along either).
"""

from __future__ import annotations

import errno
import os
import re
from pathlib import Path

import numpy as np

from fem_anim.errors import FemAnimError
from fem_anim.export.run_reader import RunData, read_run

__all__ = ["write_usd", "export_staged_run", "frame_rate", "time_codes", "prim_names",
           "up_axis", "usd_file_name"]


def usd_file_name(name: str) -> str:
    """The USD file of a scene in its run directory: ``<scene>.usdc``."""
    return f"{name}.usdc"


def frame_rate(times: np.ndarray) -> float:
    """The run's frame rate (frames/s): one over the first frame interval (1 for one frame)."""
    return 1.0 / float(times[1] - times[0]) if len(times) > 1 else 1.0


def time_codes(times: np.ndarray, start_frame: int) -> np.ndarray:
    """The time code of each frame, ``start_frame + t * fps``; codes within 1e-6 of an
    integer are that integer (the frame times are multiples of the frame interval)."""
    codes = start_frame + np.asarray(times) * frame_rate(times)
    nearest = np.round(codes)
    return np.where(np.abs(codes - nearest) < 1e-6, nearest, codes)


def up_axis(gravity: np.ndarray) -> str:
    """``"Y"`` or ``"Z"``: the axis gravity points against (2D scenes are Y-up; Z when
    gravity has no y or z component)."""
    g = np.zeros(3)
    g[:len(gravity)] = gravity
    if len(gravity) == 2:
        return "Y"
    return "Y" if abs(g[1]) > abs(g[2]) else "Z"


def prim_names(names: list[str]) -> list[str]:
    """Valid, distinct USD prim names for the bodies (``Tf.MakeValidIdentifier``; a name
    that repeats after it gets ``_<k>``, k its body number)."""
    from pxr import Tf

    out: list[str] = []
    for k, name in enumerate(names):
        valid = Tf.MakeValidIdentifier(name)
        out.append(valid if valid not in out else f"{valid}_{k}")
    return out


def _vec3f(a: np.ndarray):
    from pxr import Vt

    return Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(a, dtype=np.float32))


def _extent(x: np.ndarray):
    from pxr import Vt

    return Vt.Vec3fArray.FromNumpy(np.array([x.min(axis=0), x.max(axis=0)], np.float32))


def _obstacle_prims(stage, root: str, run: RunData, low: np.ndarray, high: np.ndarray) -> None:
    """The static obstacles under ``root/obstacles``."""
    from pxr import Gf, UsdGeom, Vt

    if not run.obstacles:
        return
    UsdGeom.Scope.Define(stage, f"{root}/obstacles")
    names = prim_names([o.get("name", "obstacle") for o in run.obstacles])
    center, size = 0.5 * (low + high), float(np.max(high - low))
    for name, obstacle in zip(names, run.obstacles):
        path = f"{root}/obstacles/{name}"
        if obstacle["type"] == "sphere":
            sphere = UsdGeom.Sphere.Define(stage, path)
            radius = float(obstacle["radius"])
            sphere.CreateRadiusAttr(radius)
            sphere.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(-radius), Gf.Vec3f(radius)]))
            c = np.zeros(3)
            c[:len(obstacle["center"])] = obstacle["center"]
            UsdGeom.Xformable(sphere).AddTranslateOp().Set(Gf.Vec3d(*c))
            continue
        n = np.zeros(3)
        n[:len(obstacle["normal"])] = obstacle["normal"]
        n /= np.linalg.norm(n)
        p = np.zeros(3)
        point = obstacle.get("point") or []
        p[:len(point)] = point
        foot = center - np.dot(center - p, n) * n  # the bodies' centre projected on the plane
        e1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(n, e1)  # (e1, e2, n) right-handed: the quad is counter-clockwise about n
        corners = foot + size * np.array([-e1 - e2, e1 - e2, e1 + e2, -e1 + e2])
        mesh = UsdGeom.Mesh.Define(stage, path)
        mesh.CreatePointsAttr(_vec3f(corners))
        mesh.CreateFaceVertexCountsAttr([4])
        mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
        mesh.CreateExtentAttr(_extent(corners))
        mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)


def _reason(err: Exception) -> str:
    """The last quoted message of a USD error (its text is a stack of C++ locations)."""
    quoted = re.findall(r": '([^']*)'", str(err))
    return quoted[-1] if quoted else str(err).strip().splitlines()[-1]


def write_usd(run: RunData, path: Path, start_frame: int = 1) -> None:
    """Write the run as a USD stage (binary ``.usdc``, or ``.usda`` text by suffix).

    Args:
        run: The run (:func:`fem_anim.export.run_reader.read_run`).
        path: The file to create (replaced if it exists; the caller checks ownership).
        start_frame: The time code of frame 0.

    Raises:
        OSError: if USD cannot write the file (naming it).
    """
    from pxr import Sdf, Tf, Usd, UsdGeom, Vt

    path = Path(path)
    try:
        stage = Usd.Stage.CreateNew(str(path))
    except Tf.ErrorException as err:
        raise OSError(errno.EIO, f"USD cannot create it: {_reason(err)}", str(path)) from None
    fps = frame_rate(run.times)
    codes = time_codes(run.times, start_frame)
    stage.SetTimeCodesPerSecond(fps)
    stage.SetFramesPerSecond(fps)
    stage.SetStartTimeCode(float(codes[0]))
    stage.SetEndTimeCode(float(codes[-1]))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if up_axis(run.gravity) == "Y"
                           else UsdGeom.Tokens.z)
    root = "/" + Tf.MakeValidIdentifier(run.name)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, root).GetPrim())
    surfaces, rest = run.surfaces(), run.surface_points()
    meshes = []
    for surface, name in zip(surfaces, prim_names(run.body_names)):
        mesh = UsdGeom.Mesh.Define(stage, f"{root}/{name}")
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray([3] * surface.triangles.shape[0]))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(
            np.ascontiguousarray(surface.triangles.ravel(), dtype=np.int32)))
        mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        primvars = UsdGeom.PrimvarsAPI(mesh)
        if surface.body in run.shells:  # a cloth: no inside, both faces seen
            mesh.CreateDoubleSidedAttr(True)
        primvars.CreatePrimvar("body", Sdf.ValueTypeNames.Int, UsdGeom.Tokens.constant) \
            .Set(surface.body)
        energy = primvars.CreatePrimvar("energy_density", Sdf.ValueTypeNames.FloatArray,
                                        UsdGeom.Tokens.uniform)
        energy.GetAttr().SetDocumentation(
            f"mean strain energy density of the cell behind each face, "
            f"{run.energy_unit(surface.body)}")
        meshes.append((mesh, surface,
                       primvars.CreatePrimvar("displacement", Sdf.ValueTypeNames.FloatArray,
                                              UsdGeom.Tokens.vertex), energy))
    low, high = np.full(3, np.inf), np.full(3, -np.inf)
    for k, code in enumerate(codes):
        u = run.surface_displacement(k)
        x = rest + u
        psi = run.energy_density(k)
        time = Usd.TimeCode(float(code))
        for mesh, surface, displacement, energy in meshes:
            xs = x[surface.vertices]
            mesh.GetPointsAttr().Set(_vec3f(xs), time)
            mesh.GetExtentAttr().Set(_extent(xs), time)
            displacement.Set(Vt.FloatArray.FromNumpy(np.linalg.norm(
                u[surface.vertices], axis=1).astype(np.float32)), time)
            energy.Set(Vt.FloatArray.FromNumpy(psi[surface.owner].astype(np.float32)), time)
        low, high = np.minimum(low, x.min(axis=0)), np.maximum(high, x.max(axis=0))
    _obstacle_prims(stage, root, run, low, high)
    try:
        stage.GetRootLayer().Save()
    except Tf.ErrorException as err:
        raise OSError(errno.EIO, f"USD cannot write it: {_reason(err)}", str(path)) from None


def export_staged_run(staging: Path, name: str, comm, start_frame: int = 1) -> None:
    """``[output] usd = true``: write ``<scene>.usdc`` into a run's staging area (rank 0).

    The stage is written to a temporary name and renamed, so the file is complete or
    absent; it is installed with the run's other files.

    Args:
        staging: The staging area holding the run's trajectory and scene.
        name: The scene's name.
        comm: The run's communicator (only rank 0 writes).
        start_frame: The time code of frame 0 (``output.start_frame``).

    Raises:
        OSError: (rank 0) if the file cannot be written, naming it.
    """
    if comm.rank != 0:
        return
    target = Path(staging) / usd_file_name(name)
    tmp = target.with_name(f".{target.stem}.tmp{target.suffix}")
    try:
        try:
            run = read_run(staging)
        except FemAnimError as err:
            raise OSError(errno.EIO, str(err), str(target)) from None
        write_usd(run, tmp, start_frame)
        os.replace(tmp, target)
    except OSError as err:
        raise OSError(err.errno, err.strerror, str(target)) from None
    finally:
        tmp.unlink(missing_ok=True)
