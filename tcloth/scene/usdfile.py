"""OpenUSD in: a mesh prim's vertices, faces and texture coordinates, for cloth from any
mesh (``Scene.add_mesh_cloth`` with a .usd, .usda, .usdc or .usdz path).

OpenUSD comes from usd-core, the optional extra ``usd`` (``pip install -e ".[usd]"``),
imported only here and in ``render/usd.py`` and only when a USD file is read or written;
without it they raise ``MissingExtraError`` saying how to install it.

The mesh is read as tcloth sees a scene: its points at the stage's earliest time (the
default value, or else the first time sample), through its prims' transforms into the
world, in metres (the stage's ``metersPerUnit``; a stage that does not say is in
centimetres, USD's fallback, as Blender reads it too) with y up (a stage whose ``upAxis`` is Z
is turned about x: z up becomes y up, as Blender's importer does the other way). Faces
listed in ``holeIndices`` are left out; a ``leftHanded`` mesh's faces are reversed, so that
every face is counter-clockwise seen from its front. Texture coordinates: the ``st``
primvar, or else the first texture-coordinate primvar, at any interpolation, indexed or
not. A file that cannot be opened, a prim path with no prim or with a prim that is not a
Mesh, a mesh without faces or with face indices out of range raise ``SceneError`` in one
line naming the file and the prim.
"""
import importlib
import os
import re

import numpy as np

from ..errors import MissingExtraError, SceneError

USD_EXTENSIONS = (".usd", ".usda", ".usdc", ".usdz")
INSTALL = 'pip install -e ".[usd]"'


def pxr_modules(*names):
    """The named modules of OpenUSD's ``pxr`` package (e.g. "Usd", "UsdGeom"), or
    MissingExtraError naming the extra that brings them."""
    try:
        return tuple(importlib.import_module(f"pxr.{name}") for name in names)
    except ImportError:
        raise MissingExtraError(f"USD files need usd-core, tcloth's optional extra 'usd': "
                                f"{INSTALL} (or pip install usd-core)") from None


def pxr_reason(error):
    """The messages of a pxr error (Tf.ErrorException) on one line, without the C++
    function, file and line each is prefixed with."""
    text = " ".join(str(error).split())
    said = re.findall(r"in file \S+ : '(.*?)'(?= Error in |$)", text)
    return "; ".join(said) if said else text


def is_usd(path):
    """Whether a path names a USD file (by its extension)."""
    return os.path.splitext(str(path))[1].lower() in USD_EXTENSIONS


def load_usd(path, prim=None):
    """(vertices (V,3) float64 in metres, y up; faces: a list of tuples of 0-based vertex
    ids, each of 3 or more) of a Mesh prim of a USD file, as ``load_obj`` gives an OBJ's.
    prim: its path in the stage, e.g. "/World/cloth"; None: the only Mesh, or the first
    in the stage's order."""
    vertices, faces, _ = read_usd(path, prim)
    return vertices, faces


def read_usd(path, prim=None):
    """``load_usd``'s (vertices, faces) and the faces' texture coordinates: a list of
    (n, 2) float64 arrays, one (u, v) per corner of each face, or None where the mesh has
    none (this module's docstring says what is read)."""
    Usd, UsdGeom = pxr_modules("Usd", "UsdGeom")
    stage = _open(Usd, path)
    mesh = _mesh_prim(UsdGeom, stage, path, prim)
    where = f"{path}: prim {str(mesh.GetPath())!r}"
    time = Usd.TimeCode.EarliestTime()
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(time) or [], dtype=np.int64)
    indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(time) or [], dtype=np.int64)
    points = np.asarray(mesh.GetPointsAttr().Get(time) or [], dtype=np.float64).reshape(-1, 3)
    if len(counts) == 0:
        raise SceneError(f"{where}: the mesh has no faces")
    if counts.min() < 3 or counts.sum() != len(indices):
        raise SceneError(f"{where}: faceVertexCounts must be 3 or more each and add up to "
                         f"the {len(indices)} faceVertexIndices (got {counts.sum()} in all, "
                         f"least {counts.min()})")
    if indices.min() < 0 or indices.max() >= len(points):
        raise SceneError(f"{where}: a face vertex index is outside the {len(points)} points")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    corners = [np.arange(s, s + n) for s, n in zip(starts, counts)]
    if mesh.GetOrientationAttr().Get(time) == UsdGeom.Tokens.leftHanded:
        corners = [c[::-1] for c in corners]
    holes = set(np.asarray(mesh.GetHoleIndicesAttr().Get(time) or [], dtype=np.int64).tolist())
    corners = [c for k, c in enumerate(corners) if k not in holes]
    if not corners:
        raise SceneError(f"{where}: the mesh has no faces (every face is a hole)")
    faces = [tuple(int(i) for i in indices[c]) for c in corners]
    uv = _corner_uvs(UsdGeom, mesh, time, where, counts, indices, len(points))
    uvs = None if uv is None else [uv[c] for c in corners]
    return _world(UsdGeom, stage, mesh, time, points), faces, uvs


def _open(Usd, path):
    if not os.path.isfile(path):
        raise SceneError(f"cannot read USD file {str(path)!r}: no such file")
    try:
        return Usd.Stage.Open(str(path), Usd.Stage.LoadAll)
    except Exception as e:      # pxr raises Tf.ErrorException, not a subclass of OSError
        raise SceneError(f"cannot read USD file {str(path)!r}: {pxr_reason(e)}") from None


def _mesh_prim(UsdGeom, stage, path, prim):
    """The UsdGeom.Mesh at ``prim``, or the first Mesh in the stage where prim is None."""
    if prim is None:
        found = next((p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)), None)
        if found is None:
            raise SceneError(f"{path}: the file has no Mesh prim")
        return UsdGeom.Mesh(found)
    if not isinstance(prim, str) or not prim.startswith("/"):
        raise SceneError(f"prim must be an absolute prim path such as '/World/cloth' "
                         f"(got {prim!r})")
    found = stage.GetPrimAtPath(prim)
    if not found.IsValid():
        raise SceneError(f"{path}: prim {prim!r} does not exist")
    if not found.IsA(UsdGeom.Mesh):
        kind = found.GetTypeName() or "typeless prim"
        raise SceneError(f"{path}: prim {prim!r} is a {kind}, not a Mesh")
    return UsdGeom.Mesh(found)


def _corner_uvs(UsdGeom, mesh, time, where, counts, indices, point_count):
    """(sum(counts), 2) texture coordinates, one per face corner in the faces' order, of
    the mesh's ``st`` primvar or its first texture-coordinate one; None without one."""
    primvars = UsdGeom.PrimvarsAPI(mesh.GetPrim())
    candidates = [primvars.GetPrimvar("st")] + [
        p for p in primvars.GetPrimvarsWithValues() if p.GetTypeName().role == "TextureCoordinate"]
    primvar = next((p for p in candidates if p and p.HasValue()), None)
    if primvar is None:
        return None
    values = np.asarray(primvar.ComputeFlattened(time), dtype=np.float64).reshape(-1, 2)
    interpolation = primvar.GetInterpolation()
    expected = {UsdGeom.Tokens.constant: 1, UsdGeom.Tokens.uniform: len(counts),
                UsdGeom.Tokens.vertex: point_count, UsdGeom.Tokens.varying: point_count,
                UsdGeom.Tokens.faceVarying: len(indices)}[interpolation]
    if len(values) != expected:
        raise SceneError(f"{where}: primvar {primvar.GetPrimvarName()!r} has {len(values)} "
                         f"values; its interpolation {interpolation!r} needs {expected}")
    if interpolation == UsdGeom.Tokens.constant:
        return np.repeat(values, len(indices), axis=0)
    if interpolation == UsdGeom.Tokens.uniform:
        return np.repeat(values, counts, axis=0)
    if interpolation == UsdGeom.Tokens.faceVarying:
        return values
    return values[indices]


def _world(UsdGeom, stage, mesh, time, points):
    """The points through the prim's transforms, in metres with y up."""
    matrix = np.array(mesh.ComputeLocalToWorldTransform(time), dtype=np.float64)
    world = points @ matrix[:3, :3] + matrix[3, :3]      # Gf matrices act on row vectors
    world *= UsdGeom.GetStageMetersPerUnit(stage)     # unauthored: USD's fallback, 0.01 (cm)
    if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z:
        world = np.stack([world[:, 0], world[:, 2], -world[:, 1]], axis=1)
    return world
