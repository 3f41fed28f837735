"""Welds: the pairs of welded seams (``Scene.sew(..., weld=True)``) merged into one
particle each once they meet.

After every step (before the contact stage's guard, and again after it where the guard
cut the motion of one of a pair's particles more than the other's), a pair not yet welded whose particles are within its weld distance is
welded, for good; every welded pair then takes its centre of mass and its momentum's
velocity: both particles get x = (m_a x_a + m_b x_b) / (m_a + m_b) and the same mean of
v (a pinned particle, of infinite mass, keeps the pair where it is). For a step that
moves each particle by its own force over its own mass (symplectic Euler), that is
exactly one particle of mass m_a + m_b under the sum of both forces; for the implicit
solvers the pair is joined by its seam spring within the step and merged at its end.
Nothing is recompiled: the terms keep their index fields, and the merged topology is
what ``Simulator.triangles()`` gives (each pair's second particle replaced by its first),
as the exports and the crossing checks read it.
"""
import numpy as np
import taichi as ti

from .. import runtime
from ..runtime import serial


@ti.kernel
def _merge(welds: ti.template(), state: ti.template()) -> ti.i32:
    return welds.merge(state)


@ti.data_oriented
class Welds:
    """The scene's welded seams as fields: pairs (K,) of 2 x i32, distance (K,) m,
    welded (K,) i32 (1 once the pair has met)."""

    def __init__(self, model, default_distance):
        scene = model.scene
        pairs = np.concatenate([w["pairs"] for w in scene.welds])
        distance = np.concatenate([
            np.full(len(w["pairs"]), default_distance if w["distance"] is None
                    else w["distance"]) for w in scene.welds])
        self.count = len(pairs)
        self.inv_mass = model.inv_mass
        self.pairs = ti.Vector.field(2, ti.i32, shape=self.count)
        self.pairs.from_numpy(pairs.astype(np.int32))
        self.distance = ti.field(runtime.real(), shape=self.count)
        self.distance.from_numpy(distance.astype(runtime.numpy_real()))
        self.welded = ti.field(ti.i32, shape=self.count)

    def reset(self):
        self.welded.fill(0)

    def apply(self, state):
        """Weld the pairs that met and merge every welded pair; the number welded so far."""
        return _merge(self, state)

    def welded_pairs(self):
        """(W, 2) the welded pairs (a, b), in the order sewn."""
        return self.pairs.to_numpy()[self.welded.to_numpy() == 1].astype(np.int64)

    @ti.func
    def merge(self, state):
        x, v, w = ti.static(state.x, state.v, self.inv_mass)
        total = 0
        ti.loop_config(serialize=ti.static(serial(self.pairs)))
        for k in range(self.count):
            a, b = self.pairs[k][0], self.pairs[k][1]
            if self.welded[k] == 0 and (x[a] - x[b]).norm() <= self.distance[k]:
                self.welded[k] = 1
            wsum = w[a] + w[b]
            if self.welded[k] == 1 and wsum > 0.0:
                # the centre of mass: m_a x_a + m_b x_b over m_a + m_b, as inverse masses
                xm = (w[b] * x[a] + w[a] * x[b]) / wsum
                vm = (w[b] * v[a] + w[a] * v[b]) / wsum
                x[a], x[b], v[a], v[b] = xm, xm, vm, vm
            total += self.welded[k]
        return total
