"""A scene's colliders checked with NumPy alone: every particle's signed distance to the
analytic colliders, the particle paths through a thin box in one step, and those through a
rigid mesh collider (in the mesh's own frame, ``crossings.count_paths_through``)."""
import numpy as np

from ..scene.meshcollider import world_vertices
from .crossings import count_paths_through


def signed_distances(scene, x, t):
    """(N, colliders) signed distance of every particle to every collider at time t."""
    out = np.zeros((len(x), len(scene.colliders)))
    for k, c in enumerate(scene.colliders):
        centre = np.asarray(c["center"]) + t * np.asarray(c["velocity"])
        if c["kind"] == "sphere":
            out[:, k] = np.linalg.norm(x - centre, axis=1) - c["radius"]
        elif c["kind"] == "plane":
            out[:, k] = (x - centre) @ np.asarray(c["normal"])
        elif c["kind"] == "box":
            q = (x - centre) @ np.asarray(c["rotation"])
            d = np.abs(q) - np.asarray(c["half_extents"])
            outside = np.linalg.norm(np.maximum(d, 0.0), axis=1)
            out[:, k] = np.where(outside > 0.0, outside, d.max(axis=1))
        else:
            raise ValueError(f"no NumPy distance for a {c['kind']}")
    return out


def passes_through_boxes(scene, x0, x1, t0, dt):
    """How many particle paths x0 -> x1 cross a box collider from one side to the other
    (slab test on the segment in the box's frame, moving with it)."""
    through = 0
    for c in scene.colliders:
        if c["kind"] != "box":
            continue
        rot, half = np.asarray(c["rotation"]), np.asarray(c["half_extents"])
        o = (x0 - (np.asarray(c["center"]) + t0 * np.asarray(c["velocity"]))) @ rot
        d = (x1 - x0 - dt * np.asarray(c["velocity"])) @ rot
        with np.errstate(divide="ignore", invalid="ignore"):
            t_a, t_b = (-half - o) / d, (half - o) / d
        lo = np.nanmax(np.minimum(t_a, t_b), axis=1)
        hi = np.nanmin(np.maximum(t_a, t_b), axis=1)
        outside_start = (np.abs(o) > half).any(axis=1)
        outside_end = (np.abs(o + d) > half).any(axis=1)
        through += int((outside_start & outside_end & (lo <= hi) & (lo > 0) & (hi < 1)).sum())
    return through


def pose(c, t):
    """(centre, rotation) of a rigid mesh collider at t, from its vertices (least squares
    of the map from its own frame to the world)."""
    own = np.asarray(c["vertices"], dtype=np.float64)
    m, *_ = np.linalg.lstsq(np.c_[own, np.ones(len(own))], world_vertices(c, t), rcond=None)
    return m[3], m[:3].T


def paths_through(c, x0, x1, t0, t1):
    """How many particle paths x0 -> x1 (over t0 .. t1) pass through the rigid mesh
    collider c, each path a segment in the mesh's own frame."""
    (c0, r0), (c1, r1) = pose(c, t0), pose(c, t1)
    return count_paths_through((x0 - c0) @ r0, (x1 - c1) @ r1, c["vertices"], c["faces"])
