"""The adjoint of a step's first collider sweep (``contact/guard.py``,
``sweep_colliders``), from its cuts as the forward run kept them (``guard.SweepLog``).

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
from ..contact.guard import BACK_OFF, PATH
from ..geometry.shapes import SHAPES


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
        npr, k = runtime.numpy_real(), len(particle)
        for field, values in ((self.particle, particle), (self.row, row), (self.kind, kind),
                              (self.tau, tau)):
            padded = np.zeros(field.shape[0], dtype=values.dtype)
            padded[:k] = values
            field.from_numpy(padded)
        self.count[None] = k
        for field, values in ((self.x0, x0), (self.x1, x1), (self.v1, v1)):
            field.from_numpy(values.astype(npr))
            field.grad.fill(0)
        seeds = []
        for values in (x_bar, v_bar):
            seed = np.zeros_like(values)
            seed[:k] = values[particle]
            seeds.append(seed.astype(npr))
        self.x_out.grad.from_numpy(seeds[0])
        self.v_out.grad.from_numpy(seeds[1])
        self._cut()
        self._cut.grad()
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
                    phi0, _ = self._distance(k, start)
                    target = ti.max(ti.min(self.table.data[k].thickness, phi0), BACK_OFF)
                    phi, n = self._distance(k, start + self.tau[c] * r)
                    end = start + (self.tau[c] - (phi - target) / n.dot(r)) * r
                _, n = self._distance(k, end)
                v = self.v1[p]
                vn = v.dot(n)
                if vn < 0.0:
                    v -= vn * n
                self.x_out[c] = end
                self.v_out[c] = v
