"""OpenUSD out: a simulation as one animated stage, for Blender, Houdini, Omniverse, Maya
(docs/usd.md). usd-core is the optional extra ``usd``; without it ``MissingExtraError``
says how to install it (``scene/usdfile.py``, which reads USD meshes in).

The stage: ``/World`` (the default prim) holds
  - ``Cloths/cloth_<k>``: a ``Mesh`` per cloth, its triangles (counter-clockwise seen
    from the front, written once, no subdivision, double-sided; with tearing, those that
    hold, at the first frame and at every frame where a tear changed them), its ``points``,
    ``normals`` (area-weighted, per vertex) and ``extent`` at every frame, ``primvars:st``
    where the cloth has texture coordinates (grid cloths; meshes whose file or arrays
    gave them), ``primvars:displayColor`` the renderer's front colour for it and
    ``primvars:pinned`` (bool, per vertex);
  - ``Ropes/rope_<k>``: a linear ``BasisCurves`` per rope, ``Particles``: a ``Points``
    of the particles in no cloth and no rope, both as wide as the renderer draws them;
  - ``Colliders/<shape>_<k>`` (k: the collider's index in ``scene.colliders``): a mesh
    collider as a ``Mesh`` of its triangles in the world (its points sampled every frame
    where it moves), a ``Sphere``, a ``Cube`` scaled to the box, a ``Cylinder`` or a ``Capsule`` along its
    local y axis, and a plane as a large thin ``Mesh`` (checkered as the ground is drawn,
    of side six times the scene's extent); translated, turned and scaled by xformOps,
    the translation sampled at every frame where the collider moves, and its visibility
    where ``sim.set_collider_enabled`` switches it.
Frame k (the first: the state when writing began) is at time code k; the stage says y up,
1 metre per unit, ``timeCodesPerSecond`` and ``framesPerSecond`` = fps, start 0 and end
the last frame written. Points are float32.

Nothing partial is left looking complete: the stage is kept in memory and written to
``NAME.partial.EXT`` when it is closed, then renamed.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Optional, Sequence

import os
import shutil
import tempfile

import numpy as np

from ..errors import SceneError
from ..geometry.primitives import vertex_normals
from ..geometry.shapes import shape_of
from ..scene.meshcollider import moves, world_vertices
from ..scene.usdfile import USD_EXTENSIONS, pxr_modules, pxr_reason
from ..validate import as_scalar
from ..version import __version__
from .drawables import COLLIDER_COLOUR, PARTICLE_COLOUR, cloth_palette, particle_spheres
from .framing import ground_and_checker
from .video import check_writable, record

if TYPE_CHECKING:
    from ..sim.simulator import Simulator

PLANE_HALF = 3.0    # a plane collider is a square of side 2 PLANE_HALF times the extent


def check_usd_path(path):
    """The path, once its extension is a USD one and its folder can be written (made if
    missing); else SceneError naming it. Also MissingExtraError without usd-core."""
    if not isinstance(path, (str, os.PathLike)) or \
            os.path.splitext(str(path))[1].lower() not in USD_EXTENSIONS:
        raise SceneError(f"a USD path must end in {', '.join(USD_EXTENSIONS)} (got {path!r})")
    pxr_modules("Usd")
    try:
        check_writable(str(path))
    except SceneError as e:
        raise SceneError(f"cannot write USD file {str(path)!r}: {e}") from None
    if os.path.isdir(path):
        raise SceneError(f"cannot write USD file {str(path)!r}: it is a folder")
    return str(path)


class UsdWriter:
    """One OpenUSD stage of a simulator's frames (this module's docstring says what is in
    it), written a frame at a time: ``write()`` after each frame's steps, ``close()`` at
    the end; ``abort()`` leaves nothing. ``tcloth.record(..., writers=[writer])`` drives
    one beside the video, ``record_usd`` alone; a loop of one's own (the viewer's, say)
    may too.

    Args:
        sim: the Simulator.
        path: .usda (text), .usdc or .usd (binary) or .usdz (a package).
        fps: frames per second of the time codes (the video's).
        cloth_colours: as the renderer takes it (its default).
        particle_radius: as the renderer takes it (its default).
    """
    label = "USD"

    def __init__(self, sim, path, fps=30, cloth_colours=None, particle_radius=None):
        self.path = check_usd_path(path)
        fps = as_scalar("fps", fps, minimum=0.0, strict=True)
        Usd, UsdGeom = pxr_modules("Usd", "UsdGeom")
        self.sim, self.count = sim, 0
        self.stage = stage = Usd.Stage.CreateInMemory()
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
        UsdGeom.SetStageMetersPerUnit(stage, 1.0)
        stage.SetTimeCodesPerSecond(fps)
        stage.SetFramesPerSecond(fps)
        stage.SetStartTimeCode(0)
        stage.SetEndTimeCode(0)
        stage.GetRootLayer().customLayerData = {"creator": f"tcloth {__version__}"}
        stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/World").GetPrim())
        for group in ("Cloths", "Ropes", "Colliders"):
            UsdGeom.Xform.Define(stage, f"/World/{group}")
        scene = sim.scene
        x0 = scene.positions
        extent = float(np.linalg.norm(x0.max(0) - x0.min(0))) or 1.0    # as the renderer's
        _, radius = particle_spheres(scene, particle_radius, extent)
        palette = cloth_palette(cloth_colours, len(scene.cloths))
        first = np.cumsum([0] + [len(c.triangles) for c in scene.cloths])
        self.parts = [_cloth(stage, k, c, palette[k, 0], scene.pinned,
                             _held(sim, first[k], first[k + 1]))
                      for k, c in enumerate(scene.cloths)]
        self.parts += [_strand(stage, f"/World/Ropes/rope_{k}", r.particles, radius,
                               scene.pinned) for k, r in enumerate(scene.ropes)]
        alone = _free_particles(scene)
        if len(alone):
            self.parts.append(_strand(stage, "/World/Particles", alone, radius, scene.pinned,
                                      rope=False))
        tile = ground_and_checker(scene, False, extent)[1]
        self.parts += [_collider(stage, k, c, sim, PLANE_HALF * extent, tile)
                       for k, c in enumerate(scene.colliders)]

    def write(self):
        """Add the simulator's current state as the next frame."""
        Sdf, = pxr_modules("Sdf")
        self.sim._check()
        x, t = self.sim.positions(), self.sim.time
        with Sdf.ChangeBlock():
            for part in self.parts:
                part(x, t, self.count)
        self.stage.SetEndTimeCode(self.count)
        self.count += 1

    def close(self):
        """Write the stage's frames so far to ``path`` (through ``NAME.partial.EXT``)."""
        root, ext = os.path.splitext(self.path)
        partial = root + ".partial" + ext
        try:
            written = _export(self.stage.GetRootLayer(), partial, os.path.basename(root))
        except Exception as e:      # pxr raises Tf.ErrorException
            written, reason = False, pxr_reason(e)
        else:
            reason = "usd-core wrote nothing"
        if not written:
            if os.path.exists(partial):
                os.remove(partial)
            raise SceneError(f"cannot write USD file {self.path!r}: {reason}")
        os.replace(partial, self.path)

    def abort(self):
        """Drop the frames: nothing was written to disk yet."""
        self.parts = []


def record_usd(sim: Simulator, path: str, frames: int = 120,
               steps_per_frame: Optional[int] = None, *, fps: float = 30, progress: bool = True,
               cloth_colours: Optional[Sequence] = None,
               particle_radius: Optional[float] = None) -> None:
    """Simulate ``frames`` frames into one OpenUSD stage at ``path``, as ``tcloth.record``
    renders them (the first frame is the current state; a progress bar on stderr).

    Args:
        path: .usda, .usdc, .usd or .usdz. steps_per_frame: simulator steps between
            frames; None: as many as fill a frame of 1/fps s, round(1 / (fps dt)), at
            least 1. cloth_colours, particle_radius: as the renderer's.
    Returns:
        ``record``'s stats, path the USD file's (write_ms_per_frame: the USD part).
    On InstabilityError the frames up to the last good one are written to ``path`` and
    the error is raised again with the frame count added to its message.
    """
    fps = as_scalar("fps", fps, minimum=0.0, strict=True)
    if steps_per_frame is None:
        steps_per_frame = max(1, round(1.0 / (fps * sim.dt)))
    writer = UsdWriter(sim, path, fps, cloth_colours, particle_radius)
    stats = record(sim, None, frames=frames, steps_per_frame=steps_per_frame, fps=fps,
                   progress=progress, writers=[writer])
    return {**stats, "path": writer.path}


def _export(layer, path, name):
    """Write a layer to ``path`` in the format its extension names; a .usdz packs it as
    NAME.usdc. Returns whether usd-core says it wrote it."""
    if not path.lower().endswith(".usdz"):
        return layer.Export(path)
    UsdUtils, Sdf = pxr_modules("UsdUtils", "Sdf")
    folder = tempfile.mkdtemp(prefix="tcloth-usd-")
    try:
        inner = os.path.join(folder, name + ".usdc")
        return layer.Export(inner) and UsdUtils.CreateNewUsdzPackage(Sdf.AssetPath(inner), path)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def _free_particles(scene):
    """The particles in no cloth and no rope."""
    taken = np.zeros(scene.num_particles, dtype=bool)
    for part in scene.cloths + scene.ropes:
        taken[np.ravel(part.particles)] = True
    return np.flatnonzero(~taken)


def _vec3f(values):
    Vt, = pxr_modules("Vt")
    return Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(values, dtype=np.float32))


def _primvar(prim, name, type_name, interpolation, value):
    UsdGeom, Sdf = pxr_modules("UsdGeom", "Sdf")
    UsdGeom.PrimvarsAPI(prim).CreatePrimvar(
        name, getattr(Sdf.ValueTypeNames, type_name), interpolation).Set(value)


def _colour(gprim, rgb, interpolation="constant"):
    gprim.CreateDisplayColorPrimvar(interpolation).Set(_vec3f(np.reshape(rgb, (-1, 3))))


def _pinned(gprim, ids, pinned):
    Vt, = pxr_modules("Vt")
    _primvar(gprim.GetPrim(), "pinned", "BoolArray", "vertex",
             Vt.BoolArray.FromNumpy(np.asarray(pinned)[ids]))


def _st(uv, triangles, count):
    """(values, interpolation) of ``primvars:st``: one (u, v) a vertex where every corner
    of a vertex has the same, else one a triangle corner."""
    per_vertex = np.zeros((count, 2))
    per_vertex[triangles] = uv
    if np.array_equal(per_vertex[triangles], uv):
        return per_vertex, "vertex"
    return uv.reshape(-1, 2), "faceVarying"


def _held(sim, begin, end):
    """None for a simulator without tearing, else a function () -> (the version of its
    surface, which of the cloth triangles ``scene.triangles[begin:end]`` hold)."""
    if sim.scene.tearing is None:
        return None
    return lambda: (sim.surface_version, sim.surface()[begin:end])


def _cloth(stage, k, cloth, colour, pinned, held=None):
    """Define cloth k's Mesh; returns its frame writer (x, t, time code). held: None (its
    triangles written once), or ``_held``'s function: the triangles that hold written at
    the first frame and at every frame where a tear changed them (time-varying
    topology; faceVarying texture coordinates follow them)."""
    Usd, UsdGeom, Vt = pxr_modules("Usd", "UsdGeom", "Vt")
    ids = np.ravel(cloth.particles)
    local = np.asarray(cloth.triangles - cloth.offset, dtype=np.int32)
    mesh = UsdGeom.Mesh.Define(stage, f"/World/Cloths/cloth_{k}")
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateDoubleSidedAttr(True)
    counts, indices = mesh.CreateFaceVertexCountsAttr(), mesh.CreateFaceVertexIndicesAttr()
    _colour(mesh, colour)
    _pinned(mesh, ids, pinned)
    st = None
    if cloth.uv is not None:
        values, interpolation = _st(cloth.uv, local, len(ids))
        _primvar(mesh.GetPrim(), "st", "TexCoord2fArray", interpolation,
                 Vt.Vec2fArray.FromNumpy(values.astype(np.float32)))
        if interpolation == "faceVarying" and held is not None:
            st = UsdGeom.PrimvarsAPI(mesh.GetPrim()).GetPrimvar("st")
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    points, normals, extent = (mesh.CreatePointsAttr(), mesh.CreateNormalsAttr(),
                               mesh.CreateExtentAttr())
    shown = {"version": None, "faces": local}

    def topology(keep, code):
        """The faces ``keep`` at time code ``code`` (None: once, for all time)."""
        code = Usd.TimeCode.Default() if code is None else code
        faces = shown["faces"] = local[keep]
        counts.Set(Vt.IntArray.FromNumpy(np.full(len(faces), 3, np.int32)), code)
        indices.Set(Vt.IntArray.FromNumpy(faces.ravel()), code)
        if st is not None:
            st.Set(Vt.Vec2fArray.FromNumpy(cloth.uv[keep].reshape(-1, 2).astype(np.float32)),
                   code)
    if held is None:
        topology(np.ones(len(local), bool), None)

    def write(x, t, code):
        if held is not None:
            version, keep = held()
            if version != shown["version"]:
                shown["version"] = version
                topology(keep, code)
        p = x[ids].astype(np.float32)
        points.Set(_vec3f(p), code)
        normals.Set(_vec3f(vertex_normals(p, shown["faces"])), code)
        extent.Set(_vec3f([p.min(0), p.max(0)]), code)
    return write


def _strand(stage, path, ids, radius, pinned, rope=True):
    """A rope's linear BasisCurves (rope False: a Points of loose particles), ``radius``
    wide; returns its frame writer."""
    UsdGeom, Vt = pxr_modules("UsdGeom", "Vt")
    if rope:
        prim = UsdGeom.BasisCurves.Define(stage, path)
        prim.CreateTypeAttr(UsdGeom.Tokens.linear)
        prim.CreateCurveVertexCountsAttr(Vt.IntArray([len(ids)]))
    else:
        prim = UsdGeom.Points.Define(stage, path)
    prim.CreateWidthsAttr(Vt.FloatArray([2.0 * radius]))
    prim.SetWidthsInterpolation(UsdGeom.Tokens.constant)
    _colour(prim, PARTICLE_COLOUR)
    _pinned(prim, ids, pinned)
    points, extent = prim.CreatePointsAttr(), prim.CreateExtentAttr()

    def write(x, t, code):
        p = x[ids].astype(np.float32)
        points.Set(_vec3f(p), code)
        extent.Set(_vec3f([p.min(0) - radius, p.max(0) + radius]), code)
    return write


def _collider(stage, k, c, sim, half, tile):
    """Define collider k's prim (a plane: a checkered square of side 2 half in tiles of
    side ``tile``); returns its frame writer (translation and visibility)."""
    Usd, UsdGeom, Gf = pxr_modules("Usd", "UsdGeom", "Gf")
    kind = c["kind"]
    path = f"/World/Colliders/{kind}_{k}"
    if kind == "mesh":
        return _mesh_collider(stage, path, k, c, sim)
    if kind == "plane":
        v, tris, colours = shape_of(c).mesh(c, half, tile)
        prim = UsdGeom.Mesh.Define(stage, path)
        prim.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        prim.CreateDoubleSidedAttr(True)
        prim.CreatePointsAttr(_vec3f(v))
        prim.CreateFaceVertexCountsAttr([3] * len(tris))
        prim.CreateFaceVertexIndicesAttr(np.ravel(tris).tolist())
        prim.CreateExtentAttr(_vec3f([v.min(0), v.max(0)]))
        _colour(prim, colours, "vertex")
    else:
        schema = {"sphere": UsdGeom.Sphere, "box": UsdGeom.Cube, "cylinder": UsdGeom.Cylinder,
                  "capsule": UsdGeom.Capsule}[kind]
        prim = schema.Define(stage, path)
        if kind == "box":
            prim.CreateSizeAttr(2.0)
        else:
            prim.CreateRadiusAttr(float(c["radius"]))
        if kind in ("cylinder", "capsule"):
            prim.CreateAxisAttr(UsdGeom.Tokens.y)
            prim.CreateHeightAttr(2.0 * float(c["half_height"]))
        prim.CreateExtentAttr(UsdGeom.Boundable.ComputeExtentFromPlugins(
            prim, Usd.TimeCode.Default()))
        _colour(prim, COLLIDER_COLOUR)
    translate = prim.AddTranslateOp()
    if "rotation" in c and not np.array_equal(c["rotation"], np.eye(3)):
        # Gf matrices act on row vectors: the transpose of the rotation that acts on columns
        turn = Gf.Matrix3d(*np.asarray(c["rotation"], dtype=float).T.ravel())
        prim.AddOrientOp().Set(Gf.Quatf(turn.ExtractRotation().GetQuat()))
    if kind == "box":
        prim.AddScaleOp().Set(Gf.Vec3f(*np.asarray(c["half_extents"], dtype=float)))
    centre, velocity = np.asarray(c["center"], float), np.asarray(c["velocity"], float)
    moving = bool(np.any(velocity != 0))
    if not moving:
        translate.Set(Gf.Vec3d(*centre))

    def write(x, t, code):
        if moving:
            translate.Set(Gf.Vec3d(*(centre + t * velocity)), code)
    return _visibility(prim, k, sim, write)


def _visibility(prim, k, sim, write_pose):
    """A frame writer: ``write_pose`` then collider k's visibility where it changed."""
    UsdGeom, = pxr_modules("UsdGeom")
    shown = [True, False]        # visible at the last frame; visibility written yet

    def write(x, t, code):
        write_pose(x, t, code)
        on = k not in sim.settings["colliders_off"]
        if on != shown[0]:
            visibility = prim.GetVisibilityAttr()
            if not shown[1] and code > 0:     # before a first sample USD holds it
                visibility.Set(UsdGeom.Tokens.inherited, 0)
            visibility.Set(UsdGeom.Tokens.inherited if on else UsdGeom.Tokens.invisible, code)
            shown[:] = on, True
    return write


def _mesh_collider(stage, path, k, c, sim):
    """A mesh collider as a ``Mesh`` of its triangles, its points in the world (sampled
    every frame where it moves); returns its frame writer."""
    Usd, UsdGeom = pxr_modules("Usd", "UsdGeom")
    prim = UsdGeom.Mesh.Define(stage, path)
    prim.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    prim.CreateDoubleSidedAttr(not c["closed"])
    prim.CreateFaceVertexCountsAttr([3] * len(c["faces"]))
    prim.CreateFaceVertexIndicesAttr(np.ravel(c["faces"]).tolist())
    _colour(prim, COLLIDER_COLOUR)
    points, extent = prim.CreatePointsAttr(), prim.CreateExtentAttr()

    def pose(x, t, code):
        v = world_vertices(c, t)
        points.Set(_vec3f(v), code)
        extent.Set(_vec3f([v.min(0), v.max(0)]), code)
    if not moves(c):
        pose(None, 0.0, Usd.TimeCode.Default())
        return _visibility(prim, k, sim, lambda x, t, code: None)
    return _visibility(prim, k, sim, pose)
