"""Conservative displacement bounds: how far each particle may move from a state without
any edge crossing any triangle (Chen et al., "Offset Geometric Contact", ACM TOG 44(4),
2025, the bounds of its Section 4, here over the proximity list).

At a state y (the detection), let D be the distance of a point and a triangle, or of
two edges, that share no particle, and d_v the smallest D over the pairs particle v is
part of. If every particle moves from y by at most gamma d_v with gamma < 1/2, each
pair's four particles move by at most gamma D each, the pair's distance falls by at most
2 gamma D, and it stays apart all along the straight paths: whatever a solver does
inside those balls, nothing crosses. Pairs that are mesh neighbours count too (they do
not repel, but must not cross).

The pairs near y are the proximity list's (``broad.BroadPhase``): every pair within its
reach (thickness + skin) at its build, and so every pair not listed is at y at least the
reach less the list's relative motion since (``BroadPhase.unlisted_distance``). A particle
in no listed pair gets that floor as its d_v.

A solver detects at the step's start (``ContactStage.detect_bounds``), clamps each move
to its ball (``clamp``), and detects again at the current state after an iteration that
clamped any: the states it detects at are each reached from the last by moves inside the
balls, so the step's motion, as the polyline through them, crosses nothing. The stage's guard still checks
the straight path from the step's start to its end. A detection whose floor has fallen
below half the list's reach (particles moved relative to each other by more than half
of it since the build) has the stage build the list again at the current state first, so
that a fast cloth is not held to balls that shrink to nothing.
"""
import taichi as ti

from .. import runtime
from ..runtime import serial
from .candidates import gap

GAMMA = 0.4     # the fraction of d_v a particle may move (OGC's gamma_p, below 1/2)


@ti.data_oriented
class DisplacementBounds:
    """Each particle's ball (``origin``, ``radius``). The contact stage detects them
    (``ContactStage.detect_bounds``), which builds its proximity list again where needed."""

    def __init__(self, inv_mass, gamma=GAMMA):
        n, real = inv_mass.shape[0], runtime.real()
        self.gamma = gamma
        self.origin = ti.Vector.field(3, real, shape=n)
        self.radius = ti.field(real, shape=n)
        self.clamped = ti.field(ti.i32, shape=())
        self.detections = 0

    def detect(self, cl, count, x, floor):
        """The balls at x (which must be crossing-free) from the pairs of list cl (count
        rows) and ``floor``, a lower bound on the distance at x of every pair it leaves
        out."""
        self._detect(cl, count, x, floor)
        self.detections += 1

    @ti.kernel
    def _detect(self, cl: ti.template(), count: ti.i32, x: ti.template(), floor: float):
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            self.radius[p] = floor
            self.origin[p] = x[p]
        ti.loop_config(serialize=ti.static(serial(cl.ids)))
        for c in range(count):
            ids = cl.ids[c]
            _, g = gap(ids, cl.kind[c], x)
            d = g.norm()
            for k in ti.static(range(4)):
                ti.atomic_min(self.radius[ids[k]], d)
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            self.radius[p] *= self.gamma
        self.clamped[None] = 0

    @ti.func
    def clamp(self, p, y):
        """y moved into particle p's ball (``clamped`` counts the moves cut)."""
        d = y - self.origin[p]
        length = d.norm()
        out = y
        if length > self.radius[p]:
            out = self.origin[p] + (self.radius[p] / length) * d
            self.clamped[None] += 1
        return out

    def any_clamped(self):
        return self.clamped[None] > 0
