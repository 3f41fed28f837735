"""The mesh colliders' half-spaces inside a solve: the solver's own iterations pull the
cloth onto them, so that the guard after the step has little to move.

The guard (``obstacle.py``) keeps a step free of crossings with a half-space per cloth
vertex of each pair its motion brings close, m . x_a >= h, and projects the vertices
below them onto them after the solve. It moves only the vertices that touched: a cloth
landing on a turntable's platter had its particles past the rim held up while their
neighbours fell on (4.6 J in the springs, and the energy budget stopped the run), and a
tablecloth over a table's lip was stretched to 1.29 times its rest length. Here the
half-spaces of the motion the solve made become a stiff penalty in the solve's
incremental potential,

    E_hold = sum over a, over its half-spaces k, of W_a / 2 max(h_k - m_k . x_a, 0)^2,

W_a = HOLD (m_a / h^2 + the stiffness of its springs), and the solver iterates again:
backward Euler and VBD take it as a per-particle potential term (``incremental``, and
``hessian_block``, a bound on its Hessian), projective dynamics as a force with the isotropic bound W_a times the
number of active half-spaces on its matrix's diagonal (``pull``), XPBD as inequality
constraints in its Gauss-Seidel (``project``). The springs then carry the hold to the
cloth around. The half-spaces are frozen for the extra iterations (an active set); the
guard afterwards takes the planes of the motion as it ends.
"""
import numpy as np
import taichi as ti

from .. import runtime
from ..runtime import serial
from .obstacle_search import INACTIVE, is_cloth

HOLD = 100.0    # the penalty's stiffness, in multiples of a particle's own (inertia, springs)
SLOTS = 8       # half-spaces kept per cloth vertex (in the pairs' order; the rest dropped)


@ti.data_oriented
class Hold:
    """Each cloth vertex's half-spaces (``count``, ``m``, ``h``) and penalty weight
    (``weight``: 0, the hold off, outside ``begin``/``end``). A per-particle potential
    term for backward Euler and VBD."""
    per_particle = True

    def __init__(self, model):
        n, real = model.particle_count, runtime.real()
        self.mass, self.inv_mass = model.mass, model.inv_mass
        self.count = ti.field(ti.i32, shape=n)
        self.m = ti.Vector.field(3, real, shape=(n, SLOTS))
        self.h = ti.field(real, shape=(n, SLOTS))
        self.weight = ti.field(real, shape=n)
        self.stiffness = ti.field(real, shape=n)     # the sum of its springs' k_s
        ns = model.spring_count
        if ns:
            pairs = model.spring_pairs.to_numpy()[:ns]
            ks = model.spring_ks.to_numpy()[:ns].astype(np.float64)
            rows = np.zeros(n)
            np.add.at(rows, pairs[:, 0], ks)
            np.add.at(rows, pairs[:, 1], ks)
            self.stiffness.from_numpy(rows.astype(runtime.numpy_real()))
        self.dropped = 0            # half-spaces past SLOTS, over every hold so far

    def begin(self, rows, count, dt):
        """The half-spaces of ``count`` rows of a ``Rows`` as each vertex's list, and the
        weights for a step of dt."""
        self.dropped += int(_collect(self, rows, count))
        _weigh(self, dt)

    def end(self):
        self.weight.fill(0)
        self.count.fill(0)

    @ti.func
    def _parts(self, p, x):
        """(energy, force -grad, active half-spaces) of vertex p at x."""
        w = self.weight[p]
        e, f, active = 0.0, ti.Vector.zero(float, 3), 0
        if w > 0.0:
            for k in range(self.count[p]):
                m = self.m[p, k]
                short = self.h[p, k] - m.dot(x[p])
                if short > 0.0:
                    e += 0.5 * w * short * short
                    f += w * short * m
                    active += 1
        return e, f, active

    @ti.func
    def incremental(self, p, x, x0, h, t):
        """(energy, magnitude, gradient) of vertex p's hold at x."""
        e, f, _ = self._parts(p, x)
        return e, e, -f

    @ti.func
    def hessian_block(self, p, x, x0, h, t):
        """W_p times the active half-spaces times the identity: a bound on the hold's
        Hessian (each m m^T <= I), not the Hessian itself. With the exact blocks a vertex
        below two planes at a small angle was sent to their intersection's line in one of
        VBD's local solves (a cloth thrown at 10 m/s on a mesh sphere at 1/30: strain 3.6
        against 0.36 without the hold); the bound moves it no farther than its planes ask
        (as projective dynamics' diagonal), and backward Euler's line search keeps its
        Newton steps descending."""
        _gap, _n, active = self._parts(p, x)
        return self.weight[p] * active * ti.Matrix.identity(float, 3)

    @ti.func
    def pull(self, p, x):
        """(force, a scalar bound on its stiffness: W_p times the active half-spaces) of
        vertex p's hold at x, for projective dynamics' residual and diagonal."""
        _, f, active = self._parts(p, x)
        return f, self.weight[p] * active

    @ti.func
    def project(self, p, x):
        """Vertex p onto each of its half-spaces in turn (while the hold is on); returns
        how far it moved."""
        moved = 0.0
        if self.weight[p] > 0.0:
            for k in range(self.count[p]):
                m = self.m[p, k]
                short = self.h[p, k] - m.dot(x[p])
                if short > 0.0:
                    x[p] += short * m
                    moved += short
        return moved


@ti.kernel
def _collect(hold: ti.template(), rows: ti.template(), count: ti.i32) -> ti.i32:
    """Each free cloth vertex's half-spaces from the rows with a plane, in the rows'
    order (one thread: the lists are the same whatever the threads); returns how many
    did not fit."""
    ti.loop_config(serialize=ti.static(serial(hold.count)))
    for a in range(hold.count.shape[0]):
        hold.count[a] = 0
    dropped = 0
    ti.loop_config(serialize=True)
    for c in range(count):
        if rows.h[c] > 0.5 * INACTIVE:
            ids, kind = rows.ids[c], rows.kind[c]
            for k in ti.static(range(4)):
                if is_cloth(kind, k):
                    a = ids[k]
                    if hold.inv_mass[a] > 0.0:
                        j = hold.count[a]
                        if j < SLOTS:
                            hold.m[a, j] = rows.m[c]
                            hold.h[a, j] = rows.h[c]
                            hold.count[a] = j + 1
                        else:
                            dropped += 1
    return dropped


@ti.kernel
def _weigh(hold: ti.template(), dt: float):
    ti.loop_config(serialize=ti.static(serial(hold.count)))
    for a in range(hold.count.shape[0]):
        hold.weight[a] = 0.0
        if hold.count[a] > 0:
            hold.weight[a] = HOLD * (hold.mass[a] / (dt * dt) + hold.stiffness[a])
