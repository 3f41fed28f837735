"""Each particle's rows of a contact list, for a solver that evaluates a particle's
contacts inside its own update (VBD's sweeps: ``SelfContact.vertex_system``)."""
import taichi as ti

from ..runtime import serial
from .contact_lag import penalty_gradient, row_dissipation, unit_normal


@ti.data_oriented
class VertexRows:
    """Particle p's rows of the list ``of`` (with its lagged columns ``lag``) are
    ``entries[start[p]:start[p + 1]]``, each (row, which of the row's four particles p
    is), in the rows' order. ``layout`` counts the times ``of``, ``lag`` or ``entries``
    were new objects at an ``index``: a kernel that reads them compiles again where it
    changed."""

    def __init__(self, particle_count):
        self.start = ti.field(ti.i32, shape=particle_count + 1)
        self.count = ti.field(ti.i32, shape=particle_count)
        self.entries = None
        self.of = self.lag = None
        self.layout = 0

    def index(self, cl, rows, lag):
        """Index the first ``rows`` rows of list cl, whose lagged columns are ``lag``."""
        if self.entries is None or self.entries.shape[0] < 4 * cl.capacity:
            self.entries = ti.Vector.field(2, ti.i32, shape=4 * cl.capacity)
            self.layout += 1
        if cl is not self.of or lag is not self.lag:
            self.of, self.lag = cl, lag
            self.layout += 1
        _index(cl, rows, self.count, self.start, self.entries)

    @ti.func
    def system(self, p, x, x0, h):
        """(gradient, Hessian block, clearance) at x of particle p's rows: the penalty's
        and the lagged dissipation's, with the exact blocks alpha_j^2 k n n^T and
        alpha0_j^2 B (k the list's table's stiffness; friction's B its majorant's, as VBD
        takes the colliders', ``colliders.add_dissipation``); the clearance is the least d - T of
        its repelling rows out of contact (1e30 without one): a row's distance moves at
        most as far as p, so a move of p shorter than that brings none into contact."""
        prm = ti.static(self.of.table.params)
        g = ti.Vector.zero(float, 3)
        block = ti.Matrix.zero(float, 3, 3)
        clearance = 1e30
        for e in range(self.start[p], self.start[p + 1]):
            c, j = self.entries[e][0], self.entries[e][1]
            _ids, alpha, depth, grad = penalty_gradient(self.of, c, x)
            if self.of.repels[c]:
                if depth > 0.0:
                    n = unit_normal(grad, grad.norm())     # zero at d = 0, as the force
                    g += alpha[j] * grad
                    block += alpha[j] * alpha[j] * prm[1] * n.outer_product(n)
                else:
                    clearance = ti.min(clearance, -depth)
            _e, g_d, block_d = row_dissipation(self.of, self.lag, c, x, x0, h, True)
            a0 = self.lag.alpha0[c][j]
            g += a0 * g_d
            block += a0 * a0 * block_d
        return g, block, clearance

    @ti.func
    def energy(self, p, x, x0, h):
        """The penalty and the lagged dissipation of particle p's rows at x: the contacts'
        part of the incremental potential as a function of x[p] alone, up to a constant."""
        prm = ti.static(self.of.table.params)
        e = 0.0
        for k in range(self.start[p], self.start[p + 1]):
            c = self.entries[k][0]
            _ids, _alpha, depth, _grad = penalty_gradient(self.of, c, x)
            if self.of.repels[c] and depth > 0.0:
                e += 0.5 * prm[1] * depth * depth
            e_d, _g_d, _block_d = row_dissipation(self.of, self.lag, c, x, x0, h, True)
            e += e_d
        return e


@ti.kernel
def _index(cl: ti.template(), rows: ti.i32, count: ti.template(), start: ti.template(),
           entries: ti.template()):
    """Count each particle's rows, lay them out by a prefix sum, then list them in the
    rows' order (one thread: the order a particle's sums take is then fixed)."""
    n = count.shape[0]
    ti.loop_config(serialize=ti.static(serial(count)))
    for p in range(n):
        count[p] = 0
    ti.loop_config(serialize=ti.static(serial(cl.ids)))
    for c in range(rows):
        for j in ti.static(range(4)):
            ti.atomic_add(count[cl.ids[c][j]], 1)
    ti.loop_config(serialize=True)
    for _ in range(1):
        running = 0
        for p in range(n):
            start[p] = running
            running += count[p]
            count[p] = 0
        start[n] = running
    ti.loop_config(serialize=True)
    for c in range(rows):
        for j in ti.static(range(4)):
            p = cl.ids[c][j]
            entries[start[p] + count[p]] = ti.Vector([c, j])
            count[p] += 1
