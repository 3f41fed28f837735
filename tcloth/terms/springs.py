"""Springs: f_ij = -(k_s (|x_ij| - l0) + k_d v_ij . d) d, d = x_ij / |x_ij|, on particle i
and -f_ij on particle j of each spring (i, j), with x_ij = x_i - x_j and v_ij = v_i - v_j;
potential k_s/2 (|x_ij| - l0)^2 (energy()["spring"]). The damping acts along the spring,
so linear and angular momentum are conserved.

Two layouts give the same forces: a regular cloth grid (``grid.py``) is evaluated by a
neighbour stencil, each spring once by the particle that owns it and then gathered (no
index arrays, no atomics); every other spring by a spring list with atomic adds.

Backward Euler takes the spring energy at the end positions and the damping as the
dissipation potential k_d/(2h) ((x_ij - x0_ij) . d0)^2 with the direction d0 of the
step's start; its Hessian block per spring is exact, or made positive semi-definite by
clamping the (under compression negative) transverse stiffness k (1 - l0/|x_ij|) at 0.
Projective dynamics takes the springs in its force residual and k_s + k_d/h in its
constant matrix.
"""
import numpy as np
import taichi as ti

from ..model import grid as grid_layout
from .. import runtime
from ..geometry.graph import csr_layout
from ..model.grid import OWNED
from ..runtime import cpu, serial
from .base import ColouredConstraints, Term


# -- one spring -------------------------------------------------------------------------------
@ti.func
def spring_force(xi, xj, vi, vj, ks, kd, rest):
    """Force on particle i from spring (i, j). Coincident ends give no force (direction
    undefined; a seam's rest length 0 is its minimum, where -k_s x_ij is 0 too). Written
    as one scalar times x_ij (not times the unit vector): three multiplications fewer per
    spring (docs/benchmarks.md)."""
    d = xi - xj
    length = d.norm()
    inv = inverse(length)
    return (-(ks * (length - rest) + kd * inv * (vi - vj).dot(d)) * inv) * d


@ti.func
def inverse(length):
    """1 / length, and 0 at length 0 (``unit``)."""
    return 1.0 / length if length > 0.0 else 0.0


@ti.func
def unit(d, length):
    """d / length, and 0 at length 0: a zero-rest-length spring (a seam) whose ends meet
    then gives no force and the Hessian block k_s I, whatever tiny d underflowed to the
    zero length (d over a floor on the length would be a huge vector there)."""
    n = d * 0.0
    if length > 0.0:
        n = d / length
    return n


@ti.func
def direction(xi, xj):
    d = xi - xj
    return unit(d, d.norm())


@ti.func
def incremental(xi, xj, x0i, x0j, d0, ks, kd, rest, h):
    """(energy, gradient on i) of one spring in backward Euler's incremental potential:
    k_s/2 (l - l0)^2 + k_d/(2h) ((x_ij - x0_ij) . d0)^2."""
    d = xi - xj
    length = d.norm()
    n = d / ti.max(length, 1e-30)
    stretch = length - rest
    rel = (d - (x0i - x0j)).dot(d0)
    e = 0.5 * ks * stretch * stretch + 0.5 * kd / h * rel * rel
    return e, ks * stretch * n + kd / h * rel * d0


@ti.func
def hessian_blocks(xi, xj, ks, kd, rest, d0, h):
    """(exact, projected) 3x3 Hessian block of one spring in the incremental potential; the
    projected one clamps the transverse stiffness k (1 - l0/|x_ij|) at 0."""
    d = xi - xj
    length = d.norm()
    n = unit(d, length)
    nn = n.outer_product(n)
    transverse = 1.0 - rest / ti.max(length, 1e-30)
    eye = ti.Matrix.identity(float, 3)
    exact = ks * (nn + transverse * (eye - nn)) + kd / h * d0.outer_product(d0)
    return exact, exact + ks * ti.max(-transverse, 0.0) * (eye - nn)


# -- the spring list --------------------------------------------------------------------------
@ti.func
def list_springs(pairs, ks, kd, rest, count, x, v, f_out):
    """Springs from a list: equal and opposite forces on both ends (atomic adds)."""
    ti.loop_config(serialize=ti.static(serial(pairs)))
    for s in range(count):
        i, j = pairs[s][0], pairs[s][1]
        fi = spring_force(x[i], x[j], v[i], v[j], ks[s], kd[s], rest[s])
        f_out[i] += fi
        f_out[j] -= fi


# -- the grid stencil -------------------------------------------------------------------------
def masked(mask):
    """Whether a stencil is given the tearing's per-slot flags (``mask``: a field or None)."""
    return mask is not None


@ti.func
def _owned_springs(x, v, offset, nx, ny, i, j, g, rest, families: ti.template(),
                   grid_forces, mask: ti.template()):
    """Forces of the springs particle (i, j) owns, on it, into grid_forces[p, slot]
    (slot = 2 family + s); 0 where the other end is off the grid, or where ``mask`` (None,
    or the tearing's (particles, 6) flags) says the spring broke."""
    if 1 <= i < nx - 2 and j < ny - 2:     # no owned spring can leave the grid
        _owned_springs_checked(x, v, offset, nx, ny, i, j, g, rest, families, grid_forces,
                               mask, False)
    else:
        _owned_springs_checked(x, v, offset, nx, ny, i, j, g, rest, families, grid_forces,
                               mask, True)


@ti.func
def _owned_springs_checked(x, v, offset, nx, ny, i, j, g, rest, families: ti.template(),
                           grid_forces, mask: ti.template(), checked: ti.template()):
    """``_owned_springs``; checked: test that each spring's other end exists."""
    p = offset + j * nx + i
    xp, vp = x[p], v[p]
    for fam in ti.static(range(3)):
        if ti.static(families[fam]):
            ks, kd = grid_layout.stiffness(g, fam)
            for s in ti.static(range(2)):
                di, dj = ti.static(OWNED[fam][s][0], OWNED[fam][s][1])
                ii, jj = i + di, j + dj
                force = ti.Vector.zero(float, 3)
                if ti.static(not checked) or (0 <= ii < nx and 0 <= jj < ny):
                    q = offset + jj * nx + ii
                    force = spring_force(xp, x[q], vp, v[q], ks, kd,
                                         grid_layout.rest_length(rest, di, dj))
                if ti.static(masked(mask)):
                    force *= ti.cast(mask[p, 2 * fam + s], float)
                grid_forces[p, 2 * fam + s] = force


@ti.func
def grid_spring_sum(offset, nx, ny, i, j, families: ti.template(), grid_forces):
    """The spring force on particle (i, j) of a grid after ``owned_grid_springs``: its own
    springs' forces minus those its neighbours own with it."""
    p = offset + j * nx + i
    acc = ti.Vector.zero(float, 3)
    for fam in ti.static(range(3)):
        if ti.static(families[fam]):
            for s in ti.static(range(2)):
                di, dj = ti.static(OWNED[fam][s][0], OWNED[fam][s][1])
                acc += grid_forces[p, 2 * fam + s]
                ii, jj = i - di, j - dj
                if 0 <= ii < nx and 0 <= jj < ny:
                    acc -= grid_forces[offset + jj * nx + ii, 2 * fam + s]
    return acc


@ti.func
def owned_grid_springs(x, v, offset, nx, ny, g, families: ti.template(), grid_forces,
                       mask: ti.template()):
    """A loop over the grid: the forces of the springs each particle owns (``OWNED``)
    into grid_forces[p, 2 family + s]. g: the grid's ``GridTable.reals`` row. mask: None,
    or the tearing's per-slot flags (0: that spring broke, no force)."""
    _grid_pass(False, x, v, 0.0, offset, nx, ny, g, families, None, grid_forces, mask, None,
               grid_forces)


@ti.func
def _gather_grid(x, v, t, offset, nx, ny, i, j, families: ti.template(), first: ti.template(),
                 grid_forces, f_out):
    p = offset + j * nx + i
    acc = grid_spring_sum(offset, nx, ny, i, j, families, grid_forces)
    if ti.static(bool(first)):
        f_out[p] = first.force(p, x, v, t) + acc
    else:
        f_out[p] += acc


@ti.func
def _grid_cell(gather: ti.template(), x, v, t, offset, nx, ny, i, j, g, rest,
               families: ti.template(), first: ti.template(), grid_forces,
               mask: ti.template(), f_out: ti.template()):
    if ti.static(gather):
        _gather_grid(x, v, t, offset, nx, ny, i, j, families, first, grid_forces, f_out)
    else:
        _owned_springs(x, v, offset, nx, ny, i, j, g, rest, families, grid_forces, mask)


@ti.func
def _grid_pass(gather: ti.template(), x, v, t, offset, nx, ny, g, families: ti.template(),
               first: ti.template(), grid_forces, mask: ti.template(), f_out: ti.template(),
               written: ti.template()):
    """One loop over a grid's particles: the springs each owns into grid_forces, or (with
    ``gather``) their sums into f_out (``_gather_grid``). On CPUs rows in parallel and the
    particles of a row in order (no index division per particle), serial where the field
    it writes (``written``) is small; elsewhere every particle in parallel."""
    rest = grid_layout.rest_lengths(g)
    if ti.static(cpu()):
        ti.loop_config(serialize=ti.static(serial(written)))
        for j in range(ny):
            for i in range(nx):
                _grid_cell(gather, x, v, t, offset, nx, ny, i, j, g, rest, families, first,
                           grid_forces, mask, f_out)
    else:
        for j, i in ti.ndrange(ny, nx):
            _grid_cell(gather, x, v, t, offset, nx, ny, i, j, g, rest, families, first,
                       grid_forces, mask, f_out)


@ti.func
def grid_springs(grids, k, families: ti.template(), first: ti.template(), x, v, t,
                 grid_forces, mask: ti.template(), f_out):
    """Provot springs of cloth grid k, each evaluated once and gathered per particle (no
    atomics): every particle computes the springs it owns (``OWNED``) into grid_forces,
    then adds those and subtracts the ones its neighbours own with it.

    grids: the ``GridTable``; families: static (structural, shear, flexion) flags.
    first: None (f += springs), or a per-particle term whose force the gather sets first
    (f = its force + springs: one pass fewer), when the grid holds every particle.
    grid_forces: (particles, 6) vec3 scratch. mask: None, or the tearing's per-slot flags.
    """
    offset, nx, ny = grids.ints[k][0], grids.ints[k][1], grids.ints[k][2]
    g = grids.reals[k]
    owned_grid_springs(x, v, offset, nx, ny, g, families, grid_forces, mask)
    _grid_pass(True, x, v, t, offset, nx, ny, g, families, first, grid_forces, mask, f_out,
               f_out)


# -- diagnostics ------------------------------------------------------------------------------
@ti.kernel
def spring_sums(x: ti.template(), pairs: ti.template(), ks: ti.template(),
                rest: ti.template(), count: ti.i32, load: float, torn: ti.template(),
                alive: ti.template(), out: ti.template()) -> ti.types.vector(3, ti.f64):
    """[spring potential sum k_s/2 (|x_ij| - l0)^2, max strain (|x_ij| - l0)/l0, max
    strain of the springs whose tension k_s (|x_ij| - l0) exceeds ``load`` (N)],
    accumulated in ``out``'s type. torn: whether ``alive`` holds the tearing's per-row
    flags (a broken spring's strain is not counted; without tearing any field)."""
    out[0] = 0
    out[1] = -1e30
    out[2] = -1e30
    ti.loop_config(serialize=ti.static(serial(pairs)))
    for s in range(count):
        i, j = pairs[s][0], pairs[s][1]
        length = (x[i] - x[j]).norm()
        stretch = length - rest[s]
        out[0] += ti.cast(0.5 * ks[s] * stretch * stretch, out.dtype)
        counted = rest[s] > 0.0         # a seam (rest length 0) has no strain
        if ti.static(torn):
            if alive[s] == 0:
                counted = False
        if counted:
            strain = ti.cast(stretch / rest[s], out.dtype)
            ti.atomic_max(out[1], strain)
            if ks[s] * stretch > load:
                ti.atomic_max(out[2], strain)
    return ti.Vector([ti.cast(out[0], ti.f64), ti.cast(out[1], ti.f64),
                      ti.cast(out[2], ti.f64)])


# -- backward Euler over the spring list ------------------------------------------------------
@ti.kernel
def begin_springs(x0: ti.template(), pairs: ti.template(), count: ti.i32, d0_out: ti.template()):
    directions(x0, pairs, count, d0_out)


@ti.func
def directions(x0, pairs, count, d0_out):
    """Each spring's unit direction at positions x0 into d0_out."""
    ti.loop_config(serialize=ti.static(serial(pairs)))
    for s in range(count):
        d0_out[s] = direction(x0[pairs[s][0]], x0[pairs[s][1]])


@ti.kernel
def add_incremental(
        # Model:
        pairs: ti.template(), ks: ti.template(), kd: ti.template(), rest: ti.template(),
        count: ti.i32, adj_start: ti.template(), adj: ti.template(),
        # State in:
        x: ti.template(), x0: ti.template(), d0: ti.template(), h: float,
        with_grad: ti.template(),
        # Out:
        g_spring: ti.template(), acc_out: ti.template(), grad_out: ti.template()):
    """acc_out[0], acc_out[1] += the springs' part of the incremental potential; with_grad:
    grad_out += its gradient, per spring into g_spring and gathered per particle."""
    ti.loop_config(serialize=ti.static(serial(pairs)))
    for s in range(count):
        i, j = pairs[s][0], pairs[s][1]
        e, g = incremental(x[i], x[j], x0[i], x0[j], d0[s], ks[s], kd[s], rest[s], h)
        acc_out[0] += ti.cast(e, acc_out.dtype)
        acc_out[1] += ti.cast(e, acc_out.dtype)
        if ti.static(with_grad):
            g_spring[s] = g
    if ti.static(with_grad):
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            g = ti.Vector.zero(float, 3)
            for k in range(adj_start[p], adj_start[p + 1]):
                s = adj[k][0]
                sign = 1.0 if pairs[s][0] == p else -1.0
                g += sign * g_spring[s]
            grad_out[p] += g


@ti.data_oriented
class Springs(Term, ColouredConstraints):
    """The scene's springs: grid stencils for cloth grids, a list for the rest; for XPBD
    (``constraints=True``) compliant distance constraints (``project_constraint``).

    Attributes (besides the model's spring fields it reads):
        grids: the model's GridBlocks; spring_grids: indices of those with springs.
        sets_forces: the first grid with springs holds every particle, so its gather can
            set the force accumulator with the first term's force (``grid_springs``).
        first: None, or (where ``sets_forces``) the per-particle term whose force the
            first grid's gather sets: the ``lead`` it was built with (``Forces`` builds
            the springs with the gravity-and-drag term as their lead where they can).
    """
    name = "spring"
    implicit = "potential"
    projective = "force"
    provides = frozenset({"constraints"})
    options = {"constraints": False}

    @staticmethod
    def present(model):
        return model.spring_count > 0

    def __init__(self, model, lead=None, constraints=False):
        self.model = model
        self.count, self.list_count = model.spring_count, model.list_spring_count
        self.pairs, self.rest = model.spring_pairs, model.spring_rest
        self.ks, self.kd = model.spring_ks, model.spring_kd
        # (torn, a torn scene's per-row flags): ``spring_sums``' last arguments but one
        self.alive = ((True, model.tearing.alive) if model.tearing is not None else
                      (False, model.spring_ks))
        # the stencil's per-slot flags where a torn scene has grids (``grid_springs``)
        self.mask = (model.tearing.grid_alive if model.tearing is not None and
                     model.tearing.gridded else None)
        self.grids, self.grid_table = model.grids, model.grid_table
        self.spring_grids = [k for k, g in enumerate(self.grids) if any(g.families)]
        first = self.grids[self.spring_grids[0]] if self.spring_grids else None
        self.sets_forces = first is not None and first.covers(model.particle_count)
        if lead is not None and not self.sets_forces:
            raise ValueError("the springs' gather sets no forces here: it cannot lead with "
                             f"{type(lead).__name__}")
        self.first = lead
        self._grid_forces = None
        self._adjacency = None
        self._implicit = None
        # the tension (N) below which a spring is not held to the strain bound
        # (``stored``); the diagnostics set it from the scene's weight
        self.load = 0.0
        if constraints:
            self.inv_mass = model.inv_mass
            self.constraints_begin(self.pairs.to_numpy()[:self.count], model.particle_count, 1)

    @ti.func
    def project_constraint(self, x, x_prev, h, s):
        """Spring s as the constraint C = |x_ij| - l0 with compliance 1 / k_s and damping
        k_d (``integrators/xpbd.py``)."""
        i, j = self.pairs[s][0], self.pairs[s][1]
        wi, wj = self.inv_mass[i], self.inv_mass[j]
        d = x[i] - x[j]
        length = d.norm()
        if length > 0.0 and self.ks[s] > 0.0 and wi + wj > 0.0:
            n = d / length
            alpha = 1.0 / (self.ks[s] * h * h)
            gamma = self.kd[s] / (self.ks[s] * h)
            rate = n.dot((x[i] - x_prev[i]) - (x[j] - x_prev[j]))
            dlam = (-(length - self.rest[s]) - alpha * self.lam[s] - gamma * rate) \
                / ((1.0 + gamma) * (wi + wj) + alpha)
            x[i] += wi * dlam * n
            x[j] -= wj * dlam * n
            self.lam[s] += dlam

    def grid_forces(self):
        """The stencil's scratch: the forces of the 6 springs each particle owns."""
        if self._grid_forces is None:
            self._grid_forces = ti.Vector.field(3, runtime.real(),
                                                shape=(self.model.particle_count, 6))
        return self._grid_forces

    def batch_obstacle(self):
        if self.list_count and not serial(self.pairs):
            return f"the spring list's {self.list_count} springs run on several threads"
        return None

    @ti.func
    def accumulate(self, x, v, t, f_out):
        """f_out += spring forces (f_out = ``first``'s force + spring forces where
        ``first`` is set). Needs ``grid_forces()`` made before it compiles."""
        for k in ti.static(self.spring_grids):
            if ti.static(k == self.spring_grids[0]):
                grid_springs(self.grid_table, k, ti.static(self.grids[k].families), self.first,
                             x, v, t, self._grid_forces, self.mask, f_out)
            else:
                grid_springs(self.grid_table, k, ti.static(self.grids[k].families), None,
                             x, v, t, self._grid_forces, self.mask, f_out)
        if ti.static(self.list_count):
            list_springs(self.pairs, self.ks, self.kd, self.rest, self.list_count, x, v,
                         f_out)

    def sums(self, x, out):
        """(spring energy, max strain) over all springs."""
        values = spring_sums(x, self.pairs, self.ks, self.rest, self.count, 0.0, *self.alive,
                             out)
        return float(values[0]), float(values[1])

    def energy(self, x, t, out):
        return self.sums(x, out)[0]

    def stored(self, x, t, out):
        """(spring energy, the largest strain of a spring that pulls harder than
        ``load``): the strain bound's part of the instability test (``sim/instability.py``
        says why a spring holding no more than the scene's weight may stretch further)."""
        values = spring_sums(x, self.pairs, self.ks, self.rest, self.count, self.load,
                             *self.alive, out)
        return float(values[0]), float(values[2])

    def adjacency(self):
        """The springs at each particle, for per-particle gathers (built on first use).

        Returns (start, adj): the entries of particle p are adj[start[p]:start[p + 1]],
        each (spring row, other particle id); every spring appears at both its ends.
        """
        if self._adjacency is None:
            n = self.model.particle_count
            pairs = self.pairs.to_numpy()[:self.count].astype(np.int64)
            start, order = csr_layout(np.concatenate([pairs[:, 0], pairs[:, 1]]), n)
            rows = np.tile(np.arange(self.count), 2)
            others = np.concatenate([pairs[:, 1], pairs[:, 0]])
            adj = ti.Vector.field(2, ti.i32, shape=max(len(order), 1))
            if len(order):
                adj.from_numpy(np.stack([rows[order], others[order]], axis=1).astype(np.int32))
            first = ti.field(ti.i32, shape=n + 1)
            first.from_numpy(start.astype(np.int32))
            self._adjacency = (first, adj)
        return self._adjacency

    # -- backward Euler ----------------------------------------------------------------------
    def implicit_fields(self):
        """(d0, per-spring gradients): backward Euler's fields, made on first use."""
        if self._implicit is None:
            real = runtime.real()
            self._implicit = tuple(ti.Vector.field(3, real, shape=self.count) for _ in range(2))
        return self._implicit

    def begin_step(self, x0, t0):
        """The spring directions d0 at the step's start (``direction_at``)."""
        begin_springs(x0, self.pairs, self.count, self.implicit_fields()[0])

    @ti.func
    def begin_directions(self, x0):
        """``begin_step`` as a ``ti.func`` (``implicit_fields`` made before it compiles)."""
        directions(x0, self.pairs, self.count, self._implicit[0])

    @property
    def d0(self):
        """Spring directions at the step's start, shape (spring_count,) of vec3."""
        return self._implicit[0]

    def add_incremental(self, x, x0, h, with_grad, acc, grad):
        """acc[0] += the springs' part of E at x (acc[1] its magnitude); with_grad:
        grad += its gradient."""
        start, adj = self.adjacency()
        add_incremental(self.pairs, self.ks, self.kd, self.rest, self.count, start, adj,
                        x, x0, self._implicit[0], h, with_grad, self._implicit[1], acc, grad)
