"""The adjoints of the guard's cuts of a step's paths (``contact/guard.py``), from the cuts
as the forward run kept them: the first collider sweep's (``sweep_colliders``,
``guard.SweepLog``: ``SweepAdjoint``) and the fail-safe's (``truncate``,
``guard.TruncationLog``: ``TruncationAdjoint``).

The sweep.
A cut of kind PATH ends the particle's path x0 -> x1 at e = x0 + tau r (r = x1 - x0)
where it meets the collider's offset surface, phi(e) = T with T = max(min(thickness,
phi(x0)), BACK_OFF); tau is the root of phi(x0 + tau r) - T, so by the implicit function
theorem its derivative is -(d phi - dT) / (n . r), n = grad phi at e. The kernel writes tau
as one Newton step from the kept root, tau_k - (phi(x0 + tau_k r) - T) / (n . r): its value
is tau_k (the residual is rounding) and its derivative the implicit one. A cut of kind
START ends at e = x0. Either way the velocity then loses its part into the collider,
v1 - min(v1 . n, 0) n with n = grad phi(e), whose derivative takes the surface's
curvature (the derivative of n in e). Taichi's reverse mode differentiates all of it
through the collider table's own ``distance`` (the colliders are at rest:
``adjoint.unsupported``).
"""
import numpy as np
import taichi as ti

from .. import runtime
from ..contact.guard import BACK_OFF, PATH, dividing_plane, stop_fraction
from ..contact.normals import chosen_margin, logged_kind, vertex_normals
from ..geometry.shapes import SHAPES


def run_cuts(adjoint, columns, x0, x1, v1, x_out_bar, v_out_bar):
    """One cut adjoint's reverse run: its records (``columns``: (field, values) pairs,
    padded to the fields), the step's start and the motion cut (x0, x1, v1: their
    gradients zeroed), and the outputs' adjoints (one row a record) as the seed of its
    ``_cut`` kernel's reverse mode; the inputs' adjoints are then in x0.grad, x1.grad,
    v1.grad."""
    npr, k = runtime.numpy_real(), len(x_out_bar)
    for field, values in columns:
        padded = np.zeros((field.shape[0],) + values.shape[1:], dtype=values.dtype)
        padded[:k] = values
        field.from_numpy(padded)
    adjoint.count[None] = k
    for field, values in ((adjoint.x0, x0), (adjoint.x1, x1), (adjoint.v1, v1)):
        field.from_numpy(values.astype(npr))
        field.grad.fill(0)
    for field, values in ((adjoint.x_out, x_out_bar), (adjoint.v_out, v_out_bar)):
        seed = np.zeros((field.shape[0], 3))
        seed[:k] = values
        field.grad.from_numpy(seed.astype(npr))
    adjoint._cut()
    adjoint._cut.grad()


@ti.data_oriented
class SweepAdjoint:
    """The vector-Jacobian product of one step's first collider sweep (``vjp``), over
    ``table`` (the adjoint's collider table, whose parameters carry gradients) for n
    particles."""

    def __init__(self, table, n):
        real = runtime.real()
        self.table = table
        self.x0, self.x1, self.v1, self.x_out, self.v_out = (
            ti.Vector.field(3, real, shape=n, needs_grad=True) for _ in range(5))
        self.particle, self.row, self.kind = (ti.field(ti.i32, shape=n) for _ in range(3))
        self.tau = ti.field(real, shape=n)
        self.capacity = n
        self.count = ti.field(ti.i32, shape=())

    def vjp(self, cuts, x0, x1, v1, x_bar, v_bar):
        """The adjoints of the sweep's inputs from those of its output (NumPy (n, 3)):
        cuts = (particle, row, kind, tau) of ``SweepLog.entries``; x0 the step's start,
        x1, v1 the solver's end of the step. Returns (x1_bar, v1_bar, x0_bar): a particle
        the sweep did not cut passes its adjoints through."""
        particle, row, kind, tau = cuts
        run_cuts(self, ((self.particle, particle), (self.row, row), (self.kind, kind),
                        (self.tau, tau)), x0, x1, v1, x_bar[particle], v_bar[particle])
        x1_bar, v1_bar = x_bar.copy(), v_bar.copy()
        x1_bar[particle] = self.x1.grad.to_numpy()[particle]
        v1_bar[particle] = self.v1.grad.to_numpy()[particle]
        return x1_bar, v1_bar, self.x0.grad.to_numpy().astype(np.float64)

    @ti.func
    def _distance(self, k, x):
        """(phi, outward normal) of x against the collider in row k (at rest)."""
        phi, n = 0.0, ti.Vector.zero(float, 3)
        for g in ti.static(self.table.groups):
            if ti.static(not SHAPES[g.shape].meshed):
                if g.first <= k and k < g.first + g.count:
                    phi, n = self.table.distance(g.shape, self.table.data[k], x, 0.0)
        return phi, n

    @ti.kernel
    def _cut(self):
        """Each kept cut c: the particle's end x_out[c] and velocity v_out[c] (module)."""
        for c in range(self.capacity):
            if c < self.count[None]:
                p, k = self.particle[c], self.row[c]
                start = self.x0[p]
                end = start
                if self.kind[c] == PATH:
                    r = self.x1[p] - start
                    phi0, _n0 = self._distance(k, start)
                    target = ti.max(ti.min(self.table.data[k].thickness, phi0), BACK_OFF)
                    phi, n = self._distance(k, start + self.tau[c] * r)
                    end = start + (self.tau[c] - (phi - target) / n.dot(r)) * r
                _phi, n = self._distance(k, end)
                v = self.v1[p]
                vn = v.dot(n)
                if vn < 0.0:
                    v -= vn * n
                self.x_out[c] = end
                self.v_out[c] = v


@ti.data_oriented
class TruncationAdjoint:
    """The vector-Jacobian product of one step's fail-safe (``vjp``) for n particles of
    a self-collision ``table``: a vertex p stopped by candidate (ids, kind) ends at x0 +
    t (x1 - x0) with velocity t v1, t = KEEP (its distance to the dividing plane at x0) /
    (its approach to it), the plane normal to the candidate's n (from x0 and the vertex
    normals there, ``normals.chosen_margin``) between the sides' extents, placed by
    their speeds (``guard.dividing_plane``), all differentiated by Taichi's reverse
    mode."""

    def __init__(self, table, n):
        real = runtime.real()
        self.table, self.thickness = table, table.params
        self.x0, self.x1, self.v1, self.x_out, self.v_out, self.normals = (
            ti.Vector.field(3, real, shape=n, needs_grad=True) for _ in range(6))
        self.particle, self.kind, self.slot = (ti.field(ti.i32, shape=n) for _ in range(3))
        self.ids = ti.Vector.field(4, ti.i32, shape=n)
        self.capacity = n
        self.count = ti.field(ti.i32, shape=())

    def vjp(self, truncation, x0, x_bar, v_bar):
        """The adjoints of the fail-safe's input (the motion it cut, x1 and v1, kept with
        its cuts: ``frozen.StepRecord``) from those of its output, and the step start's
        share. Returns (x1_bar, v1_bar, x0_bar)."""
        (particle, ids, kind, slot), x1, v1 = truncation
        self.normals.grad.fill(0)
        run_cuts(self, ((self.particle, particle), (self.ids, ids), (self.kind, kind),
                        (self.slot, slot)), x0, x1, v1, x_bar[particle], v_bar[particle])
        x1_bar, v1_bar = x_bar.copy(), v_bar.copy()
        x1_bar[particle] = 0.0
        v1_bar[particle] = 0.0
        x1_bar += self.x1.grad.to_numpy()
        v1_bar += self.v1.grad.to_numpy()
        return x1_bar, v1_bar, self.x0.grad.to_numpy().astype(np.float64)

    @ti.kernel
    def _cut(self):
        """Each kept cut c: the vertex's end x_out[c] and velocity v_out[c] (class)."""
        vertex_normals(self.table, self.x0, self.normals)
        for c in range(self.capacity):
            if c < self.count[None]:
                p, ids, slot = self.particle[c], self.ids[c], self.slot[c]
                kind, choice = logged_kind(self.kind[c])
                n, _margin, _delta = chosen_margin(ids, kind, choice, self.x0, self.thickness[0],
                                        self.normals)
                _side, plane, first = dividing_plane(ids, kind, n, self.x0, self.x1)
                side = 1.0 if slot < first else -1.0
                t = stop_fraction(self.x0, self.x1, n, plane, side, p)
                self.x_out[c] = self.x0[p] + t * (self.x1[p] - self.x0[p])
                self.v_out[c] = t * self.v1[p]
