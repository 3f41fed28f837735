"""The hinges of a cloth's triangles and their weights, in NumPy (``terms/bending.py``
derives them and simulates the energy; the builders check a fabric's mesh with them)."""
import numpy as np

from ..errors import SceneError

FOLD_TOLERANCE = 1e-3        # the largest rest fold (radians) a hinge may have


def hinge_table(triangles, x):
    """The hinges of triangles (T,3) at rest positions x (N,3): (ids (H,4): edge ends
    x0, x1 and opposite vertices x2, x3; K (H,4); A (H,): both triangles' rest area;
    fold (H,): the rest dihedral angle, radians), NumPy f64."""
    tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    x = np.asarray(x, dtype=np.float64)
    a = tris.ravel()
    b = np.roll(tris, -1, axis=1).ravel()
    c = np.roll(tris, -2, axis=1).ravel()
    key = np.stack([np.minimum(a, b), np.maximum(a, b)], 1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    order = np.argsort(inverse, kind="stable")
    edge = inverse[order]                   # a shared edge's two sides are neighbours here
    same = np.flatnonzero((edge[1:] == edge[:-1]) & (counts[edge[1:]] == 2))
    first, second = order[same], order[same + 1]
    ids = np.stack([a[first], b[first], c[first], c[second]], 1)
    x0, x1, x2, x3 = (x[ids[:, k]] for k in range(4))
    e0, e1, e2, e3, e4 = x1 - x0, x2 - x0, x3 - x0, x2 - x1, x3 - x1

    def cot(u, v):
        return np.einsum("ij,ij->i", u, v) / np.linalg.norm(np.cross(u, v), axis=1)

    c01, c02, c03, c04 = cot(e0, e1), cot(e0, e2), cot(-e0, e3), cot(-e0, e4)
    K = np.stack([c03 + c04, c01 + c02, -c01 - c03, -c02 - c04], 1)
    n1, n2 = np.cross(e0, e1), np.cross(e2, e0)
    area = 0.5 * (np.linalg.norm(n1, axis=1) + np.linalg.norm(n2, axis=1))
    cosine = np.einsum("ij,ij->i", n1, n2) / (np.linalg.norm(n1, axis=1)
                                             * np.linalg.norm(n2, axis=1))
    return ids, K, area, np.arccos(np.clip(cosine, -1.0, 1.0))


def check_flat(ids, fold):
    """SceneError unless every hinge (ids (H,4), rest folds (H,) radians) is flat."""
    if len(fold) and fold.max() > FOLD_TOLERANCE:
        h = int(np.argmax(fold))
        raise SceneError(f"bending needs a flat rest shape: the hinge at particles "
                         f"{ids[h, 0]}-{ids[h, 1]} is folded by "
                         f"{np.degrees(fold[h]):.3g} degrees at rest")


def cloth_hinge_parts(cloth, rest):
    """(ids (H,4), K (H,4), area (H,), family (H,), share (H,)) of one cloth's hinges at
    rest positions ``rest`` (N,3): each hinge's rigidity is share * rigidity[family]
    (family 0 warp, 1 weft; a grid's hinges take half of it, a mesh's all of its one)."""
    ids, K, area, fold = hinge_table(cloth.triangles, rest)
    check_flat(ids, fold)
    if not cloth.is_grid:
        return ids, K, area, np.zeros(len(ids), np.int64), np.ones(len(ids))
    p = cloth.particles
    a, b, c, d = p[:-1, :-1], p[:-1, 1:], p[1:, 1:], p[1:, :-1]
    crossed = np.concatenate([np.stack([a, d, c], -1).reshape(-1, 3),
                              np.stack([a, c, b], -1).reshape(-1, 3)])
    ids, K, area = (np.concatenate(z) for z in zip(
        (ids, K, area), hinge_table(crossed, rest)[:3]))
    nx = cloth.resolution[0]
    di = (ids[:, 1] - cloth.offset) % nx - (ids[:, 0] - cloth.offset) % nx
    dj = (ids[:, 1] - cloth.offset) // nx - (ids[:, 0] - cloth.offset) // nx
    leg = (di == 0) | (dj == 0)
    return (ids[leg], K[leg], area[leg], (di[leg] != 0).astype(np.int64),
            np.full(int(leg.sum()), 0.5))


def hinge_weights(K, area, share, rigidity):
    """The hinges' scaled weights c = sqrt(B_e / A_e) K, B_e = share * rigidity (H,)."""
    return np.sqrt(share * rigidity / area)[:, None] * K


def cloth_hinges(cloth, rest, rigidity):
    """(ids (H,4), c (H,4)): the hinges of one cloth and their scaled weights
    c = sqrt(B_e / A_e) K at rest positions ``rest`` (N,3); rigidity (warp, weft)."""
    if not cloth.is_grid and rigidity[0] != rigidity[1]:
        raise SceneError(f"a (warp, weft) bending rigidity needs a grid cloth: a mesh cloth "
                         f"has no warp and weft (got {list(rigidity)})")
    ids, K, area, family, share = cloth_hinge_parts(cloth, rest)
    return ids, hinge_weights(K, area, share, np.asarray(rigidity, np.float64)[family])
