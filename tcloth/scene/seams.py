"""Seams: ``Scene.sew``, zero-rest-length springs that pull pairs of particles together and,
with ``weld``, merge each pair into one once they meet (docs/sewing.md).

A seam spring is an ordinary spring of kind "seam" with rest length 0: its force
-k_s x_ij - k_d (v_ij . d) d is linear in x_ij and its energy k_s/2 |x_ij|^2 has its minimum
where the ends meet, so every integrator takes it as it takes the other springs
(``terms/springs.py`` gives coincident ends no force and the Hessian k_s I). What seams
change elsewhere: self-contact treats a pair as one particle (``contact/topology.py``:
each end is a mesh neighbour of the other and of the other's neighbours), and welds are
the simulator's (``sim/welds.py``).
"""
import numpy as np

from ..errors import SceneError
from ..validate import as_scalar, fmt


def _ids(name, values, n):
    try:
        ids = np.asarray(values)
    except (TypeError, ValueError):
        ids = None
    if ids is None or ids.ndim != 1 or len(ids) == 0 or ids.dtype.kind not in "iu":
        raise SceneError(f"{name} must be a non-empty 1-D array of particle ids "
                         f"(got {fmt(values)})")
    ids = ids.astype(np.int64)
    if ids.min() < 0 or ids.max() >= n:
        bad = int(ids[(ids < 0) | (ids >= n)][0])
        raise SceneError(f"{name} holds particle id {bad}, outside [0, {n})")
    if len(np.unique(ids)) != len(ids):
        raise SceneError(f"{name} repeats a particle id (got {fmt(values)})")
    return ids


def sew(scene, a, b, stiffness, damping, weld, weld_distance):
    """``Scene.sew``: checks, the seam springs, and the weld's record in ``scene.welds``."""
    n = scene.num_particles
    a, b = _ids("a", a, n), _ids("b", b, n)
    if len(a) != len(b):
        raise SceneError(f"a and b must pair particles one to one (got {len(a)} and "
                         f"{len(b)} ids)")
    if np.intersect1d(a, b).size:
        raise SceneError(f"a and b share particle {int(np.intersect1d(a, b)[0])}: a seam "
                         "joins two different particles")
    if not isinstance(weld, (bool, np.bool_)):
        raise SceneError(f"weld must be True or False (got {weld!r})")
    distance = None if weld_distance is None else \
        as_scalar("weld_distance", weld_distance, minimum=0.0, strict=True)
    if weld:
        taken = np.concatenate([w["pairs"].ravel() for w in scene.welds]
                               + [np.zeros(0, np.int64)])
        both = np.concatenate([a, b])
        clash = np.isin(both, taken)
        if clash.any():
            raise SceneError(f"particle {int(both[clash][0])} is already in a welded seam "
                             "(a particle welds to one other at most)")
    springs = scene.add_springs(np.stack([a, b], 1), stiffness, damping, rest_length=0.0,
                                kind="seam")
    if weld:
        scene.welds.append({"pairs": np.stack([a, b], 1), "distance": distance})
    return springs
