"""Cloth meshes out: OBJ (text) and PLY (binary) for Blender and friends."""
import os

import numpy as np

from ..errors import SceneError


def cloth_mesh(sim):
    """(vertices (V,3), faces (F,3)) of the cloth triangles that hold (all of them, but
    those a tear cut: ``Simulator.surface``) at the current state; vertices are the cloth
    particles only, each welded seam's pair as one (``sim.triangles()``), faces index them
    from 0."""
    scene = sim.scene
    if not scene.cloths:
        raise SceneError("the scene has no cloth to export (mesh export writes cloth triangles)")
    ids = np.concatenate([c.particles.ravel() for c in scene.cloths])
    ids = ids[~np.isin(ids, sim.welded()[:, 1])]
    remap = np.full(scene.num_particles, -1, dtype=np.int64)
    remap[ids] = np.arange(len(ids))
    faces = remap[sim.triangles()[sim.surface()]]
    return sim.positions()[ids].astype(np.float64), faces


def write_obj(path, vertices, faces):
    """Wavefront OBJ: ``v x y z`` lines (17 significant digits: ``load_obj`` reads the
    same numbers back) then 1-based ``f a b c`` lines."""
    with open(path, "w") as f:
        f.write("# tcloth cloth mesh\n")
        np.savetxt(f, vertices, fmt="v %.17g %.17g %.17g")
        np.savetxt(f, faces + 1, fmt="f %d %d %d")


def write_ply(path, vertices, faces):
    """Binary little-endian PLY with float32 vertices and int32 triangle lists."""
    header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(vertices)}\n"
              "property float x\nproperty float y\nproperty float z\n"
              f"element face {len(faces)}\nproperty list uchar int vertex_indices\n"
              "end_header\n").encode()
    tri = np.empty(len(faces), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    tri["n"] = 3
    tri["i"] = faces
    with open(path, "wb") as f:
        f.write(header)
        f.write(np.asarray(vertices, dtype="<f4").tobytes())
        f.write(tri.tobytes())


def export_mesh(sim, path):
    """Write the simulator's cloth mesh to ``path`` (.obj or .ply by extension)."""
    ext = os.path.splitext(path)[1].lower()
    writers = {".obj": write_obj, ".ply": write_ply}
    if ext not in writers:
        raise SceneError(f"mesh path must end in .obj or .ply (got {path!r})")
    writers[ext](path, *cloth_mesh(sim))
