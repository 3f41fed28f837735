"""``Scene.add_mesh_collider``: any triangle mesh as an obstacle, and its motion.

The collider dict (kind "mesh") holds the mesh in its own frame, scaled: ``vertices``
(V, 3) and ``faces`` (F, 3) (polygons fanned into triangles as ``add_mesh_cloth`` does;
a closed mesh's faces turned outward), ``closed``, and its pose at t = 0 (``center``,
``rotation``) with one motion:

  - rigid and constant: ``velocity`` (m/s) and ``spin`` (the angular velocity, rad/s,
    about the mesh's origin): at t it is turned by exp(t [spin]) and moved by t velocity;
  - ``keyframes``: [(time, position, rotation), ...], positions linear and rotations
    spherical-linear between them, held before the first and after the last;
  - ``deform``: a callable t -> (V, 3) vertices in the mesh's own frame, or a (frames, V,
    3) array of them at ``deform_fps`` (linear between frames, the last one held),
    placed by the pose.

``step_pose(c, t0, dt)`` gives a keyframed collider's row for one step (a constant
velocity and spin that take its pose at t0 to its pose at t0 + dt), and
``world_vertices(c, t)`` any mesh collider's vertices in the world at t.
"""
import warnings

import numpy as np

from ..errors import SceneError
from ..validate import as_points, as_rotation, as_scalar, as_vec3, fmt
from .builders import check_faces, fan, read_mesh
from ..geometry import trimesh
from ..geometry.sdf import plan

REACH = 0.25     # m: how far from the mesh its distance is searched, beyond the thickness


def _mesh_input(mesh, prim):
    """(vertices, faces as tuples, name) of an OBJ or USD path, or of (vertices, faces)."""
    if isinstance(mesh, (str, bytes)) or hasattr(mesh, "__fspath__"):
        vertices, faces, _ = read_mesh(mesh, prim)
        return vertices, faces, str(mesh)
    try:
        vertices, faces = mesh
    except (TypeError, ValueError):
        raise SceneError("mesh must be an OBJ or USD path or a (vertices, faces) pair "
                         f"(got {fmt(mesh)})") from None
    return vertices, [tuple(f) for f in np.asarray(faces).tolist()] \
        if isinstance(faces, np.ndarray) else list(faces), "mesh"


def _scale(value):
    s = np.asarray(value, dtype=np.float64) if np.ndim(value) else np.full(3, float(value))
    if s.shape != (3,) or not np.all(np.isfinite(s)) or np.any(s <= 0.0):
        raise SceneError(f"scale must be a positive number or three (got {fmt(value)})")
    return s


def _keyframes(keyframes):
    out = []
    try:
        rows = list(keyframes)
    except TypeError:
        raise SceneError(f"keyframes must be a list of (time, position, rotation) "
                         f"(got {fmt(keyframes)})") from None
    for k, row in enumerate(rows):
        if len(row) != 3:
            raise SceneError(f"keyframes[{k}] must be (time, position, rotation) "
                             f"(got {fmt(row)})")
        out.append((as_scalar(f"keyframes[{k}] time", row[0]),
                    as_vec3(f"keyframes[{k}] position", row[1]),
                    as_rotation(f"keyframes[{k}] rotation", row[2])))
    times = [t for t, _, _ in out]
    if not out or np.any(np.diff(times) <= 0.0):
        raise SceneError(f"keyframes need one or more rows with increasing times (got times "
                         f"{fmt(times)})")
    return out


def _deform(deform, count):
    """The deform callable or array, checked: (V, 3) finite vertices, V = count."""
    if callable(deform):
        deformed_vertices(deform, 0.0, count, 1.0, None)
        return deform
    frames = np.asarray(deform, dtype=np.float64)
    if frames.ndim != 3 or frames.shape[1:] != (count, 3):
        raise SceneError(f"deform must be a callable or a (frames, {count}, 3) array of the "
                         f"mesh's {count} vertices (got shape {frames.shape})")
    if not np.all(np.isfinite(frames)):
        raise SceneError("deform's vertices must be finite (frame "
                         f"{np.argwhere(~np.isfinite(frames))[0][0]} is not)")
    return frames


def deformed_vertices(deform, t, count, scale, fps):
    """A deforming mesh's vertices in its own frame at t, scaled, checked."""
    if callable(deform):
        v = deform(t)
        try:
            v = np.asarray(v, dtype=np.float64)
        except (TypeError, ValueError):
            raise SceneError(f"deform({t}) must give (V, 3) numbers (got {fmt(v)})") from None
        if v.shape != (count, 3):
            raise SceneError(f"deform({t}) gave vertices of shape {v.shape}; the mesh has "
                             f"{count} vertices (its vertex count cannot change)")
        if not np.all(np.isfinite(v)):
            raise SceneError(f"deform({t}) gave a vertex that is not finite (vertex "
                             f"{np.argwhere(~np.isfinite(v))[0][0]})")
    else:
        s = min(max(t * fps, 0.0), len(deform) - 1)
        k = min(int(s), len(deform) - 2) if len(deform) > 1 else 0
        f = s - k
        v = deform[k] if len(deform) == 1 else (1 - f) * deform[k] + f * deform[k + 1]
    return v * scale


def add_mesh_collider(scene, mesh, position, rotation, scale, common, velocity,
                      angular_velocity, keyframes, deform, deform_fps, prim, sdf="auto"):
    """``Scene.add_mesh_collider`` (its docstring); ``common`` the arguments every
    collider takes, for ``Scene.add_collider``."""
    if not (isinstance(sdf, bool) or isinstance(sdf, str) and sdf == "auto"):
        raise SceneError(f"sdf must be \"auto\", True or False (got {fmt(sdf)})")
    vertices, faces, name = _mesh_input(mesh, prim)
    vertices = as_points(f"{name}'s vertices", vertices)
    try:
        checked, _, _ = check_faces(vertices, faces)
    except SceneError as e:
        raise SceneError(f"{name}: {e}") from None
    triangles, _ = fan(checked)
    scale = _scale(scale)
    motions = [m for m, given in (("velocity/angular_velocity", velocity is not None
                                   or angular_velocity is not None),
                                  ("keyframes", keyframes is not None),
                                  ("deform", deform is not None)) if given]
    if len(motions) > 1:
        raise SceneError(f"a mesh collider has one motion; got {' and '.join(motions)}")
    topo = trimesh.mesh_topology(triangles)
    closed = topo["closed"]
    if len(topo["crossed"]):
        warnings.warn(f"{name}: faces {topo['crossed'][:5].tolist()} are wound against a "
                      "neighbour or share an edge with several faces: the collider is taken "
                      "as open (two-sided)", stacklevel=3)
    own = vertices * scale
    if closed and trimesh.signed_volume(own, triangles) < 0.0:
        triangles = triangles[:, ::-1].copy()
    shape = {"center": as_vec3("position", position),
             "rotation": np.eye(3) if rotation is None else as_rotation("rotation", rotation),
             "vertices": own, "faces": triangles, "closed": closed,
             "scale": scale, "spin": as_vec3("angular_velocity", angular_velocity)
             if angular_velocity is not None else np.zeros(3),
             "keyframes": None if keyframes is None else _keyframes(keyframes),
             "deform": None if deform is None else _deform(deform, len(own)),
             "deform_fps": as_scalar("deform_fps", deform_fps, minimum=0.0, strict=True),
             "reach": REACH + common["thickness"], "sdf": sdf}
    if shape["deform"] is not None:
        shape["vertices"] = deformed_vertices(shape["deform"], 0.0, len(own), scale,
                                              shape["deform_fps"])
    if shape["keyframes"] is not None:
        shape["center"], shape["rotation"] = keyframe_pose(shape["keyframes"], 0.0)
    plan(shape, closed, common["thickness"])       # sdf=True that cannot be: said now
    return scene.add_collider("mesh", shape, velocity=(0.0, 0.0, 0.0) if velocity is None
                              else velocity, **common)


def _slerp(r0, r1, f):
    """The rotation a fraction f of the way from r0 to r1 (about the axis of r1 r0^T)."""
    rel = r1 @ r0.T
    angle = np.arccos(np.clip((np.trace(rel) - 1.0) / 2.0, -1.0, 1.0))
    if angle < 1e-12:
        return r0
    axis = np.array([rel[2, 1] - rel[1, 2], rel[0, 2] - rel[2, 0], rel[1, 0] - rel[0, 1]])
    if np.linalg.norm(axis) < 1e-12:            # a half turn: the axis from rel + I
        sym = rel + np.eye(3)
        axis = sym[:, np.argmax(np.linalg.norm(sym, axis=0))]
    return rotation_about(axis / np.linalg.norm(axis), f * angle) @ r0


def rotation_about(axis, angle):
    """The rotation by ``angle`` (rad) about the unit ``axis`` (Rodrigues)."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def keyframe_pose(keyframes, t):
    """(position, rotation) of keyframes at t."""
    times = [k[0] for k in keyframes]
    if t <= times[0]:
        return keyframes[0][1], keyframes[0][2]
    if t >= times[-1]:
        return keyframes[-1][1], keyframes[-1][2]
    i = int(np.searchsorted(times, t, side="right")) - 1
    (t0, p0, r0), (t1, p1, r1) = keyframes[i], keyframes[i + 1]
    f = (t - t0) / (t1 - t0)
    return (1 - f) * p0 + f * p1, _slerp(r0, r1, f)


def step_pose(c, t0, dt):
    """(center, velocity, rotation, spin) of a keyframed collider's row over the step
    from t0: its pose at t0 + s is (center + (t0 + s) velocity, exp((t0 + s) [spin])
    rotation), which meets the keyframes' at s = 0 and s = dt."""
    p0, r0 = keyframe_pose(c["keyframes"], t0)
    p1, r1 = keyframe_pose(c["keyframes"], t0 + dt)
    velocity = (p1 - p0) / dt
    rel = r1 @ r0.T
    angle = np.arccos(np.clip((np.trace(rel) - 1.0) / 2.0, -1.0, 1.0))
    spin = np.zeros(3)
    if angle > 1e-12:
        axis = np.array([rel[2, 1] - rel[1, 2], rel[0, 2] - rel[2, 0], rel[1, 0] - rel[0, 1]])
        spin = axis / np.linalg.norm(axis) * angle / dt
    back = rotation_about(spin / max(np.linalg.norm(spin), 1e-300), -np.linalg.norm(spin) * t0)
    return p0 - t0 * velocity, velocity, back @ r0, spin


def moves(c):
    """Whether a mesh collider moves at all."""
    return bool(np.any(np.asarray(c["velocity"]) != 0.0) or np.any(np.asarray(c["spin"]) != 0.0)
                or c["keyframes"] is not None or c["deform"] is not None)


def world_vertices(c, t):
    """A mesh collider's vertices in the world at t (m)."""
    if c["keyframes"] is not None:
        centre, rotation = keyframe_pose(c["keyframes"], t)
    else:
        w = np.asarray(c["spin"], dtype=np.float64)
        speed = np.linalg.norm(w)
        turn = rotation_about(w / speed, speed * t) if speed > 0 else np.eye(3)
        centre = np.asarray(c["center"]) + t * np.asarray(c["velocity"])
        rotation = turn @ np.asarray(c["rotation"])
    own = c["vertices"] if c["deform"] is None else deformed_vertices(
        c["deform"], t, len(c["vertices"]), c["scale"], c["deform_fps"])
    return own @ rotation.T + centre
