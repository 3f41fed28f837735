"""What frames a scene in both renderers (the off-screen one and the window): the height
and tile size of the drawn ground, placed below the lowest point anything can reach.
Plain NumPy from the scene."""
import heapq
import math

import numpy as np

from ..geometry.shapes import shape_of

HANG_STRETCH = 1.25     # the most a hanging spring is taken to stretch (``lowest_reach``)


def lowest_reach(scene):
    """The lowest height (y, m) a particle of ``scene`` can reach, or None when some part
    can fall without end (free particles under gravity with nothing they hang from).

    Under gravity a particle at spring-path length d (rest lengths) from a resting pinned
    particle at height y_s stays above y_s - s d, each spring stretched by at most
    s = HANG_STRETCH (or the scene's strain limit plus 5 %, if lower), for every such pin;
    so above the highest of those bounds: the shortest paths from all pins at once, each
    starting at -y_s (``_hang_depths``). A part with no resting pin falls on. Without
    gravity nothing falls: the lowest particle, less half the scene's extent (it may
    drift)."""
    x = scene.positions
    if not len(x):
        return None
    if not np.any(scene.gravity):
        return float(x[:, 1].min() - 0.5 * np.linalg.norm(np.ptp(x, axis=0)))
    stretch = HANG_STRETCH
    if scene.strain_limit is not None:
        stretch = min(stretch, 1.05 + scene.strain_limit["max_stretch"])
    anchors = np.asarray(scene.pinned, dtype=bool) & ~np.any(scene.velocities, axis=1)
    springs = scene.springs
    depth = _hang_depths(x, springs["pairs"], stretch * springs["rest_length"], anchors)
    return None if not np.isfinite(depth).all() else float(-depth.max())


def _hang_depths(x, pairs, lengths, anchors):
    """min over anchors s of (-y_s + path length from s) per particle (Dijkstra with the
    anchors' -y as their starting labels; inf where no anchor is reachable)."""
    neighbours = [[] for _ in range(len(x))]
    for (i, j), length in zip(pairs.tolist(), lengths.tolist()):
        neighbours[i].append((j, length))
        neighbours[j].append((i, length))
    depth = np.full(len(x), np.inf)
    heap = [(-float(x[i, 1]), i) for i in np.flatnonzero(anchors).tolist()]
    for d, i in heap:
        depth[i] = d
    heapq.heapify(heap)
    while heap:
        d, i = heapq.heappop(heap)
        if d > depth[i]:
            continue
        for j, length in neighbours[i]:
            if d + length < depth[j]:
                depth[j] = d + length
                heapq.heappush(heap, (d + length, j))
    return depth


def ground_and_checker(scene, ground, extent):
    """(ground, checker): the height (y, m) of the drawn ground, or False for none, and the
    side of its tiles (m). ground None draws none where the scene has checkered colliders
    (planes: drawn instead) or where something can fall without end, and otherwise puts
    it just below everything that can move (``lowest_reach``) and every collider."""
    if ground is None:
        has_planes = any(shape_of(c).checkered for c in scene.colliders)
        lowest = None if has_planes else lowest_reach(scene)
        if lowest is None:
            ground = False
        else:
            bottoms = [shape_of(c).bottom(c) for c in scene.colliders]
            ground = min([lowest] + bottoms) - 0.02 * extent
    return ground, 10.0 ** math.floor(math.log10(extent)) / 4
