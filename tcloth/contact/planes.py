"""Self-contact inside projective dynamics' step: the contact stage's separating
planes (``ContactStage.search_solve``, ``contact/guard.py``) as one-sided constraints of the
step's minimisation.

Each candidate pair keeps, for every vertex a of its first side and b of its second,
n . (x_a - x_b) >= delta (the pair's plane at the step's start). Like Liu et al.'s
constraints, each is a quadratic w / 2 |C x - p|^2 with p the projection of C x onto the
constraint's set, here the half-line [delta, inf) of the scalar C x = n . (x_a - x_b):

    E = w / 2 min(0, n . (x_a - x_b) - REACH delta)^2

held a little beyond the plane's delta (REACH), so that the pair ends the solve where
the guard finds nothing to correct. Where a vertex pair is closer than that at an
iterate (active), its force w (REACH delta - n . (x_a - x_b)) n on a (the opposite on
b) is in the force residual and its Hessian, w n n^T on the blocks aa and bb and
-w n n^T on ab and ba, in the global matrix: in CG's products (``add_product``), not on
the preconditioner's diagonal (an isotropic bound there, measured with a truncation
after every global step since dropped, took the 64 x 64 fold's conjugate gradients from
476 to 1,550 iterations a step). Only the normal is constrained, so a pair slides along
its plane freely; and each constraint's rows sum to zero, as a spring's do, so a global
solve keeps the momentum (a diagonal stand-in for w n n^T, tried, let the momentum of
two unequal cloths thrown together drift by 0.27 of their mass times their speed, 0.0003
with it). The active set is taken again at every iterate.

The weight: PLANE_STIFFNESS times A's diagonal bound (M/h^2 + the springs' weights) at
a vertex, shared among that vertex's active pairs (a vertex of a layer lies in the
planes of tens of its neighbours' candidates; summed unshared, they made A too stiff
for CG), the smaller of the pair's two shares. With 10, two cloths thrown at each other
at 10 m/s, a twisted cloth and the pile run their whole spans at one step per frame
(``docs/contact.md``); with 1 and 3 the twist tore (measured with a truncation after
every global step, which held no more than the penalty alone).
"""
import taichi as ti

from .. import runtime
from ..runtime import serial
from .normals import VERTEX_PAIRS, kept_apart, plane_row

PLANE_STIFFNESS = 10.0   # the most a vertex's constraints weigh together, over its A_pp
# active vertex pairs a particle held at first (more grows the list: the kernels that
# take it are compiled again)
PAIRS_PER_PARTICLE = 32
# a constraint holds its pair at REACH times its plane's delta: a stiff penalty still
# gives by force / w, and at delta itself that left the pair within the guard's reach
# (160 corrections after two 12 x 12 cloths thrown at 10 m/s, 23 in 30 steps of the
# 64 x 64 fold; none in either at 1.1)
REACH = 1.1


class PlaneConstraints:
    """The active vertex pairs of a projective step's planes at its current iterate
    (``gather``), their forces (``add_forces``) and their part of the global matrix
    (``add_product``, a coupling of ``linalg.PCG``, called at every CG iteration). The
    rows and their kernels are a ``_Rows``, made again where the list grows."""

    def __init__(self, n):
        self.rows = _Rows(n, PAIRS_PER_PARTICLE * n)

    @property
    def count(self):
        return self.rows.count

    def gather(self, contacts, x, inv_mass, diagonal):
        """The vertex pairs of ``contacts`` ((list, planes, rows), as the stage gives them)
        closer along their plane's normal than REACH times its delta at x, weighted from
        ``diagonal`` (A's per-particle bound); the list grown where they overflow it.
        Returns how many."""
        cl, pl, count = contacts
        while True:
            found = self.rows.gather(cl, pl, count, x, inv_mass)
            if found <= self.rows.capacity:
                break
            self.rows = _Rows(self.rows.hits.shape[0], max(2 * self.rows.capacity, found))
        self.rows.weights(diagonal)
        return found

    def add_forces(self, x, f):
        """f += the active constraints' forces at x."""
        self.rows.forces(x, f)

    def add_product(self, v, out, first):
        """out += (= when ``first``) the active constraints' Hessian w n n^T times v."""
        self.rows.product(v, out, first)


@ti.data_oriented
class _Rows:
    """The active vertex pairs (``capacity`` rows) and the kernels that read them."""

    def __init__(self, n, capacity):
        real = runtime.real()
        self.capacity = capacity
        self.hits = ti.field(real, shape=n)             # a particle's active pairs
        self.count = ti.field(ti.i32, shape=())
        self.pairs = ti.Vector.field(2, ti.i32, shape=capacity)
        self.n = ti.Vector.field(3, real, shape=capacity)
        self.gap = ti.field(real, shape=capacity)       # delta of the pair's plane
        self.w = ti.field(real, shape=capacity)

    @ti.kernel
    def gather(self, cl: ti.template(), pl: ti.template(), rows: ti.i32, x: ti.template(),
               inv_mass: ti.template()) -> ti.i32:
        self.count[None] = 0
        ti.loop_config(serialize=ti.static(serial(cl.ids)))
        for c in range(rows):
            ids, kind, n, delta = plane_row(cl, pl, c)
            for a, b in ti.static(VERTEX_PAIRS):
                if kept_apart(kind, delta, a, b):
                    pa, pb = ids[a], ids[b]
                    free = inv_mass[pa] + inv_mass[pb] > 0.0
                    if free and n.dot(x[pa] - x[pb]) < delta * REACH:
                        k = ti.atomic_add(self.count[None], 1)
                        if k < self.capacity:
                            self.pairs[k] = ti.Vector([pa, pb])
                            self.n[k] = n
                            self.gap[k] = delta * REACH
        found = self.count[None]
        self.count[None] = ti.min(found, self.capacity)
        return found

    @ti.kernel
    def weights(self, diagonal: ti.template()):
        """Each active pair's weight (module docstring)."""
        ti.loop_config(serialize=ti.static(serial(self.hits)))
        for p in range(self.hits.shape[0]):
            self.hits[p] = 0.0
        ti.loop_config(serialize=ti.static(serial(self.pairs)))
        for k in range(self.count[None]):
            self.hits[self.pairs[k][0]] += 1.0
            self.hits[self.pairs[k][1]] += 1.0
        ti.loop_config(serialize=ti.static(serial(self.pairs)))
        for k in range(self.count[None]):
            a, b = self.pairs[k][0], self.pairs[k][1]
            self.w[k] = PLANE_STIFFNESS * ti.min(diagonal[a] / self.hits[a],
                                                 diagonal[b] / self.hits[b])

    @ti.kernel
    def forces(self, x: ti.template(), f: ti.template()):
        ti.loop_config(serialize=ti.static(serial(self.pairs)))
        for k in range(self.count[None]):
            a, b = self.pairs[k][0], self.pairs[k][1]
            push = self.w[k] * ti.max(self.gap[k] - self.n[k].dot(x[a] - x[b]), 0.0)
            f[a] += push * self.n[k]
            f[b] -= push * self.n[k]

    @ti.kernel
    def product(self, v: ti.template(), out: ti.template(), first: ti.template()):
        if ti.static(first):
            ti.loop_config(serialize=ti.static(serial(out)))
            for p in range(out.shape[0]):
                out[p] = ti.Vector.zero(float, 3)
        ti.loop_config(serialize=ti.static(serial(self.pairs)))
        for k in range(self.count[None]):
            a, b = self.pairs[k][0], self.pairs[k][1]
            s = self.w[k] * self.n[k].dot(v[a] - v[b]) * self.n[k]
            out[a] += s
            out[b] -= s
