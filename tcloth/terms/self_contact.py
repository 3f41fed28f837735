"""Self-collision: cloths and ropes kept out of themselves and each other (lecture 4:
"cloth shouldn't pass through itself or through other objects").

Contacts. A contact joins four particles x_k with weights alpha_k so that the gap between
the two closest points is g = sum_k alpha_k x_k (``proximity.py``):
  - point-triangle: a particle of a cloth or rope against a cloth triangle,
    alpha = (1, -w_a, -w_b, -w_c) with w the barycentric weights of the closest point;
  - edge-edge: two cloth edges or rope segments, alpha = (1 - s, s, -(1 - u), -u) with s, u
    the closest points' parameters. Without it two edges of a fold cross where neither
    has a particle near the other's triangles.
Pairs that touch by construction never repel (``topology.py``: a shared particle, or mesh
neighbours across the two sides).

Model. With d = |g|, n = g / d and thickness T, a contact with d < T has the penalty
energy k/2 (T - d)^2 (``energy()["self_contact"]``) and pushes both sides apart along n:
each particle gets alpha_k f with

    f = f_n n - mu f_n v_t / max(|v_t|, eps),   f_n = max(k (T - d) - 2 zeta sqrt(k m) v_n, 0),

v_rel = sum_k alpha_k v_k the relative velocity of the closest points (v_n its normal and
v_t its tangential part), m = 1 / sum_k alpha_k^2 / m_k the contact's effective mass and
zeta the damping ratio: the colliders' law between two moving surfaces. Since sum_k alpha_k
= 0 the forces cancel: linear momentum is conserved. Each contact is a sum term, so a
particle above a triangle's edge or vertex also feels the neighbouring triangles (a
smooth, slightly stronger repulsion there); the force is minus the gradient of the energy
(the closest points minimise d, so their own change does not enter). A contact with d = 0
exactly has no direction and exerts nothing.

Broad phase (``hashgrid.py``, ``Search``): particles and edge midpoints are binned in
hashed uniform cells of size max(longest edge, T + skin), sorted by counting sort; each
triangle visits the particles in its box grown by T + skin, each edge the edges of higher
index whose midpoints lie in its box grown by T + skin + half the longest edge (box tests
that every pair within T + skin passes), a shared particle is skipped before the exact
distance and the exclusion rule, and pairs closer than T + skin become the candidate
list. The queries run in parallel blocks that write to their own slots, laid out by a
prefix sum, so on CPUs the list's order is that of a serial search whatever the threads.
The list is rebuilt only when twice the largest distance of a displacement since the last build
from a centre c exceeds the skin (c: the middle of the displacements' bounding box at
the previous check; |d_i - d_j| <= |d_i - c| + |d_j - c| for any c): no two particles
have then moved relative to each other by more than the skin, so no pair left out can be
closer than T, and a motion the particles share (a cloth falling) costs no rebuild. Most
evaluations only walk the candidates. A build costs O(particles + edges + table) plus,
per triangle or edge, the cells its box covers (at most 4 and 5 per axis with this cell
size) times the items per cell, which is bounded by how many layers of cloth lie within
a cell of each other.

Integrators. Explicit integrators take the force. Backward Euler takes the penalty energy
at the end positions and, like the colliders, the normal damping and friction as convex
dissipation potentials with the start of the step's normal force, normal and weights; the
Newton matrix gets each contact's Gauss-Newton Hessian (the penalty's k n n^T without
the curvature term, which is negative, and the dissipation's blocks) spread over its four
particles: the diagonal blocks in the block-Jacobi preconditioner, the couplings between
them applied matrix-free in CG's products (``add_product``). Projective dynamics projects after its
iterations: Jacobi passes over the penetrating contacts moving the particles
apart to distance T (inverse-mass weighted, averaged over each particle's contacts), then
removing approaching normal velocity and cutting tangential velocity by mu times that
(Coulomb).
"""
import taichi as ti

from .. import runtime
from ..hashgrid import HashGrid, blocks_for, exclusive_scan
from ..proximity import contact_weights
from ..runtime import serial, serial_count
from .base import Term
from .colliders import add_dissipation, contact_force

POINT_TRIANGLE, EDGE_EDGE = 0, 1
PROJECTION_PASSES = 4
# one query of the search costs about as much as this many items of the loops that
# runtime.SERIAL_BELOW was measured on, so its loop goes parallel from that many / this
SEARCH_COST = 16
QUERY_BLOCK = 64
# particles per block of the displacement test's reduction
DISPLACEMENT_BLOCK = 1024


@ti.func
def _gap(ids, kind, x):
    """(alpha, g) of a contact at positions x."""
    alpha = contact_weights(kind, x[ids[0]], x[ids[1]], x[ids[2]], x[ids[3]])
    g = ti.Vector.zero(float, 3)
    for k in ti.static(range(4)):
        g += alpha[k] * x[ids[k]]
    return alpha, g


@ti.data_oriented
class ContactList:
    """Candidate contacts (ids (4,) and kind per row) of capacity ``capacity`` and backward
    Euler's lagged values per row."""

    def __init__(self, table, inv_mass, capacity):
        real = runtime.real()
        self.table, self.inv_mass = table, inv_mass
        self.capacity = capacity
        self.ids = ti.Vector.field(4, ti.i32, shape=capacity)
        self.kind = ti.field(ti.i32, shape=capacity)
        self.lag_fn = ti.field(real, shape=capacity)
        self.lag_n = ti.Vector.field(3, real, shape=capacity)
        self.lag_alpha = ti.Vector.field(4, real, shape=capacity)
        # backward Euler's Hessian per row: the weights, penalty and dissipation blocks
        self.alpha = ti.Vector.field(4, real, shape=capacity)
        self.penalty = ti.Matrix.field(3, 3, real, shape=capacity)
        self.damping = ti.Matrix.field(3, 3, real, shape=capacity)

    @ti.func
    def gap(self, ids, kind, x):
        """(alpha, g) of a contact at positions x."""
        return _gap(ids, kind, x)

    @ti.func
    def inverse_mass(self, ids, alpha):
        """sum_k alpha_k^2 / m_k: the contact's inverse effective mass."""
        w = 0.0
        for k in ti.static(range(4)):
            w += alpha[k] * alpha[k] * self.inv_mass[ids[k]]
        return w


@ti.data_oriented
class Search:
    """The broad phase: the particles' and edge midpoints' hash grids, the positions x_ref
    of the last build, and what the queries found.

    There is one query per triangle (the particles near it) and one per edge (the edges
    of higher index near it). Blocks of QUERY_BLOCK consecutive queries run in parallel,
    each block on one thread appending what its queries find to its own ``block_slots``
    slots; a prefix sum over the queries' counts lays out the rows. On CPUs the list's
    order, and every sum over it, is therefore that of a serial search whatever the
    threads (on GPUs the order of a query's finds within one cell may vary)."""

    def __init__(self, table, inv_mass, grids, x_ref, block_slots):
        self.table, self.inv_mass = table, inv_mass
        self.points_grid, self.edges_grid = grids
        self.x_ref = x_ref
        self.queries = table.triangle_count + table.edge_count
        self.blocks = blocks_for(self.queries, QUERY_BLOCK)
        self.block_slots = block_slots
        self.found = ti.field(ti.i32, shape=self.blocks * block_slots)
        self.fill = ti.field(ti.i32, shape=self.blocks)
        self.found_count = ti.field(ti.i32, shape=self.queries)
        self.found_start = ti.field(ti.i32, shape=self.queries + 1)
        self.scan_blocks = ti.field(ti.i32, shape=blocks_for(self.queries))
        moved_blocks = blocks_for(table.point_count, DISPLACEMENT_BLOCK)
        self.moved_lo = ti.Vector.field(3, ti.f64, shape=moved_blocks)
        self.moved_hi = ti.Vector.field(3, ti.f64, shape=moved_blocks)
        self.moved_farthest = ti.field(ti.f64, shape=moved_blocks)

    @ti.func
    def _consider(self, ids, kind, n_a, query, item):
        """Record ``item`` for the query if the contact ids is not excluded, not between
        pinned particles only, and its gap at x_ref is within thickness + skin."""
        alpha, g = _gap(ids, kind, self.x_ref)
        reach = self.table.params[0] + self.table.params[5]
        if g.norm() <= reach:
            free = False
            for k in ti.static(range(4)):
                if self.inv_mass[ids[k]] > 0.0:
                    free = True
            if free and not self.table.excluded(ids, n_a):
                blk = query // QUERY_BLOCK
                k = self.fill[blk]
                if k < self.block_slots:
                    self.found[blk * self.block_slots + k] = item
                self.fill[blk] = k + 1
                self.found_count[query] += 1
        return 0

    @ti.func
    def _point_triangle(self, item, t):
        tri, p = self.table.triangles[t], self.table.points[item]
        if p != tri[0] and p != tri[1] and p != tri[2]:
            self._consider(ti.Vector([p, tri[0], tri[1], tri[2]]), POINT_TRIANGLE, 1, t, item)

    @ti.func
    def _edge_edge(self, item, e):
        a, b = self.table.edges[e], self.table.edges[item]
        if a[0] != b[0] and a[0] != b[1] and a[1] != b[0] and a[1] != b[1]:
            self._consider(ti.Vector([a[0], a[1], b[0], b[1]]), EDGE_EDGE, 2,
                           self.table.triangle_count + e, item)

    @ti.func
    def query(self, q, x, reach, longest):
        """Run query q (a triangle, then the edges) at positions x."""
        T = ti.static(self.table.triangle_count)
        self.found_count[q] = 0
        if q < T:
            tri = self.table.triangles[q]
            a, b, c = x[tri[0]], x[tri[1]], x[tri[2]]
            self.points_grid.for_each_in_box(ti.min(a, b, c) - reach,
                                             ti.max(a, b, c) + reach, -1,
                                             self._point_triangle, q)
        else:
            e = q - T
            a, b = x[self.table.edges[e][0]], x[self.table.edges[e][1]]
            grow = reach + 0.5 * longest
            self.edges_grid.for_each_in_box(ti.min(a, b) - grow, ti.max(a, b) + grow, e,
                                            self._edge_edge, e)


@ti.kernel
def _relative_displacement(search: ti.template(), x: ti.template(),
                           centre: ti.template()) -> ti.f64:
    """Twice the largest distance of a displacement x - x_ref from ``centre``: no two
    particles have moved relative to each other by more, whatever the centre, and a motion
    they share does not count. The centre is then set to the middle of this call's
    displacements' bounding box, the one the next call measures from.

    Blocks of DISPLACEMENT_BLOCK particles reduce in parallel, then one thread over the
    blocks: a reduction of all particles into one variable made the threads take turns
    on its atomic compare-and-swaps (20 ms a call for 262144 particles on two threads)."""
    P = ti.static(search.table.point_count)
    B = ti.static(blocks_for(P, DISPLACEMENT_BLOCK))
    c = centre[None]
    ti.loop_config(serialize=ti.static(serial_count(P)))
    for blk in range(B):
        lo = ti.Vector([1e30, 1e30, 1e30], ti.f64)
        hi = ti.Vector([-1e30, -1e30, -1e30], ti.f64)
        farthest = ti.cast(0.0, ti.f64)
        for i in range(blk * DISPLACEMENT_BLOCK, ti.min((blk + 1) * DISPLACEMENT_BLOCK, P)):
            p = search.table.points[i]
            d = ti.cast(x[p] - search.x_ref[p], ti.f64)
            lo, hi = ti.min(lo, d), ti.max(hi, d)
            farthest = ti.max(farthest, (d - c).norm_sqr())
        search.moved_lo[blk], search.moved_hi[blk] = lo, hi
        search.moved_farthest[blk] = farthest
    ti.loop_config(serialize=True)
    for _ in range(1):
        lo, hi = search.moved_lo[0], search.moved_hi[0]
        farthest = search.moved_farthest[0]
        for blk in range(1, B):
            lo, hi = ti.min(lo, search.moved_lo[blk]), ti.max(hi, search.moved_hi[blk])
            farthest = ti.max(farthest, search.moved_farthest[blk])
        centre[None] = 0.5 * (lo + hi)
        search.moved_farthest[0] = farthest              # the kernel returns it from there
    return 2.0 * ti.sqrt(search.moved_farthest[0])


@ti.kernel
def _rebuild(search: ti.template(), cl: ti.template(), x: ti.template(),
             centre: ti.template()) -> ti.types.vector(2, ti.i32):
    """Bin the particles and edge midpoints at x and list the candidate contacts; x_ref =
    x and the displacements' centre 0. Returns (the number of candidates, the most a
    block of queries found): more than the list's capacity or the search's block_slots
    means rebuild larger."""
    P, E, T = ti.static(cl.table.point_count, cl.table.edge_count, cl.table.triangle_count)
    Q, B, slots = ti.static(search.queries, search.blocks, search.block_slots)
    centre[None] = ti.Vector.zero(ti.f64, 3)
    ti.loop_config(serialize=ti.static(serial_count(P)))
    for i in range(P):
        p = cl.table.points[i]
        search.x_ref[p] = x[p]
        search.points_grid.pos[i] = x[p]
    longest = 0.0
    ti.loop_config(serialize=ti.static(serial_count(E)))
    for e in range(E):
        a, b = x[cl.table.edges[e][0]], x[cl.table.edges[e][1]]
        search.edges_grid.pos[e] = 0.5 * (a + b)
        ti.atomic_max(longest, (a - b).norm())
    reach = cl.table.params[0] + cl.table.params[5]
    cell = ti.max(longest, reach)
    search.points_grid.set_cell(cell)
    search.edges_grid.set_cell(cell)
    search.points_grid.build(P)
    search.edges_grid.build(E)
    ti.loop_config(serialize=ti.static(serial_count(SEARCH_COST * Q)))
    for blk in range(B):
        search.fill[blk] = 0
        for q in range(blk * QUERY_BLOCK, ti.min((blk + 1) * QUERY_BLOCK, Q)):
            search.query(q, x, reach, longest)
    exclusive_scan(search.found_count, search.found_start, search.scan_blocks, Q,
                   ti.static(serial_count(Q)), False)
    most = 0
    ti.loop_config(serialize=ti.static(serial_count(Q)))
    for blk in range(B):
        ti.atomic_max(most, search.fill[blk])
        slot = blk * slots
        for q in range(blk * QUERY_BLOCK, ti.min((blk + 1) * QUERY_BLOCK, Q)):
            row = search.found_start[q]
            for _ in range(search.found_count[q]):
                if slot < (blk + 1) * slots and row < cl.capacity:
                    item = search.found[slot]
                    if q < T:
                        tri = cl.table.triangles[q]
                        cl.ids[row] = ti.Vector([cl.table.points[item], tri[0], tri[1],
                                                 tri[2]])
                        cl.kind[row] = POINT_TRIANGLE
                    else:
                        a, b = cl.table.edges[q - T], cl.table.edges[item]
                        cl.ids[row] = ti.Vector([a[0], a[1], b[0], b[1]])
                        cl.kind[row] = EDGE_EDGE
                slot += 1
                row += 1
    return ti.Vector([search.found_start[Q], most])


@ti.func
def _normal(g, d):
    return g / ti.max(d, 1e-30)


@ti.kernel
def self_contact_forces(
        # Model:
        cl: ti.template(), count: ti.i32,
        # State in:
        x: ti.template(), v: ti.template(),
        # Out:
        f_out: ti.template()):
    """f_out += the self-contact forces of the first ``count`` candidates."""
    prm = ti.static(cl.table.params)
    ti.loop_config(serialize=ti.static(serial(cl.ids)))
    for c in range(count):
        ids, kind = cl.ids[c], cl.kind[c]
        alpha, g = cl.gap(ids, kind, x)
        d = g.norm()
        thickness, k = prm[0], prm[1]
        if d > 0.0 and d < thickness:
            n = _normal(g, d)
            v_rel = ti.Vector.zero(float, 3)
            for j in ti.static(range(4)):
                v_rel += alpha[j] * v[ids[j]]
            w = cl.inverse_mass(ids, alpha)
            if w > 0.0:
                f = contact_force(thickness - d, v_rel, n, k, 2.0 * prm[3] * ti.sqrt(k / w),
                                  prm[2], prm[4])
                for j in ti.static(range(4)):
                    f_out[ids[j]] += alpha[j] * f


@ti.kernel
def _energy(cl: ti.template(), count: ti.i32, x: ti.template(),
            out: ti.template()) -> ti.f64:
    prm = ti.static(cl.table.params)
    out[0] = 0
    ti.loop_config(serialize=ti.static(serial(cl.ids)))
    for c in range(count):
        alpha, g = cl.gap(cl.ids[c], cl.kind[c], x)
        depth = prm[0] - g.norm()
        if depth > 0.0:
            out[0] += ti.cast(0.5 * prm[1] * depth * depth, out.dtype)
    return ti.cast(out[0], ti.f64)


@ti.kernel
def _active(cl: ti.template(), count: ti.i32, x: ti.template()) -> ti.types.vector(2, ti.i32):
    """(point-triangle, edge-edge) contacts closer than the thickness."""
    pt, ee = 0, 0
    ti.loop_config(serialize=ti.static(serial(cl.ids)))
    for c in range(count):
        kind = cl.kind[c]
        alpha, g = cl.gap(cl.ids[c], kind, x)
        if g.norm() < cl.table.params[0]:
            if kind == POINT_TRIANGLE:
                pt += 1
            else:
                ee += 1
    return ti.Vector([pt, ee])


# -- backward Euler --------------------------------------------------------------------------
@ti.kernel
def _lag(cl: ti.template(), count: ti.i32, x0: ti.template()):
    """Each candidate's normal force, normal and weights at the step's start."""
    prm = ti.static(cl.table.params)
    ti.loop_config(serialize=ti.static(serial(cl.ids)))
    for c in range(count):
        alpha, g = cl.gap(cl.ids[c], cl.kind[c], x0)
        d = g.norm()
        fn = 0.0
        if d > 0.0 and d < prm[0]:
            fn = prm[1] * (prm[0] - d)
        cl.lag_fn[c] = fn
        cl.lag_n[c] = _normal(g, d)
        cl.lag_alpha[c] = alpha


@ti.func
def _dissipation(cl, c, x, x0, h):
    """(energy, gradient, Hessian) in the relative motion sum_k alpha0_k x_k of contact c's
    normal damping and friction as convex potentials of the end velocity (the colliders'
    ``add_dissipation`` between two moving sides; no damping where every particle of the
    contact is pinned)."""
    prm = ti.static(cl.table.params)
    ids, fn0 = cl.ids[c], cl.lag_fn[c]
    e = 0.0
    g = ti.Vector.zero(float, 3)
    block = ti.Matrix.zero(float, 3, 3)
    if fn0 > 0.0:
        alpha0 = cl.lag_alpha[c]
        w = cl.inverse_mass(ids, alpha0)
        v = ti.Vector.zero(float, 3)
        for j in ti.static(range(4)):
            v += alpha0[j] * (x[ids[j]] - x0[ids[j]]) / h
        cd = 0.0
        if w > 0.0:
            cd = 2.0 * prm[3] * ti.sqrt(prm[1] / w)
        e, g, block = add_dissipation(e, g, block, v, cl.lag_n[c], fn0, cd, prm[2], prm[4], h)
    return e, g, block


@ti.kernel
def _incremental(cl: ti.template(), count: ti.i32, x: ti.template(), x0: ti.template(),
                 h: float, with_grad: ti.template(), acc_out: ti.template(),
                 grad_out: ti.template()):
    """acc_out[0], acc_out[1] += the contacts' part of backward Euler's incremental
    potential; with_grad: grad_out += its gradient."""
    prm = ti.static(cl.table.params)
    ti.loop_config(serialize=ti.static(serial(cl.ids)))
    for c in range(count):
        ids = cl.ids[c]
        alpha, g = cl.gap(ids, cl.kind[c], x)
        d = g.norm()
        depth = prm[0] - d
        e = 0.0
        if depth > 0.0:
            e = 0.5 * prm[1] * depth * depth
            if ti.static(with_grad):
                grad = -prm[1] * depth * _normal(g, d)
                for j in ti.static(range(4)):
                    grad_out[ids[j]] += alpha[j] * grad
        e_d, g_d, _ = _dissipation(cl, c, x, x0, h)
        if ti.static(with_grad):
            alpha0 = cl.lag_alpha[c]
            for j in ti.static(range(4)):
                grad_out[ids[j]] += alpha0[j] * g_d
        acc_out[0] += ti.cast(e + e_d, acc_out.dtype)
        acc_out[1] += ti.cast(e + e_d, acc_out.dtype)


@ti.kernel
def _blocks(cl: ti.template(), count: ti.i32, x: ti.template(), x0: ti.template(),
            h: float, diag: ti.template()):
    """diag = each particle's diagonal blocks of the contacts' Hessian: alpha_k^2 times
    the penalty's k n n^T (without the curvature term) and the dissipation's block."""
    prm = ti.static(cl.table.params)
    ti.loop_config(serialize=ti.static(serial(diag)))
    for p in range(diag.shape[0]):
        diag[p] = ti.Matrix.zero(float, 3, 3)
    ti.loop_config(serialize=ti.static(serial(cl.ids)))
    for c in range(count):
        ids = cl.ids[c]
        alpha, g = cl.gap(ids, cl.kind[c], x)
        d = g.norm()
        penalty = ti.Matrix.zero(float, 3, 3)
        if d < prm[0]:
            n = _normal(g, d)
            penalty = prm[1] * n.outer_product(n)
        _, _, block = _dissipation(cl, c, x, x0, h)
        alpha0 = cl.lag_alpha[c]
        cl.alpha[c] = alpha
        cl.penalty[c] = penalty
        cl.damping[c] = block
        for j in ti.static(range(4)):
            diag[ids[j]] += alpha[j] * alpha[j] * penalty + alpha0[j] * alpha0[j] * block


@ti.kernel
def _couplings(cl: ti.template(), count: ti.i32, v: ti.template(), out: ti.template(),
               first: ti.template()):
    """out += (= when ``first``) the contacts' Hessian without its diagonal blocks times
    v: sum over contacts of alpha_j P (u - alpha_j v_j) + alpha0_j B (u0 - alpha0_j v_j) at
    each of its particles j, u = sum_k alpha_k v_k (u0 with alpha0), P and B the penalty
    and dissipation blocks stored by ``_blocks``."""
    if ti.static(first):
        ti.loop_config(serialize=ti.static(serial(out)))
        for p in range(out.shape[0]):
            out[p] = ti.Vector.zero(float, 3)
    ti.loop_config(serialize=ti.static(serial(cl.ids)))
    for c in range(count):
        ids, a, a0 = cl.ids[c], cl.alpha[c], cl.lag_alpha[c]
        u = ti.Vector.zero(float, 3)
        u0 = ti.Vector.zero(float, 3)
        for j in ti.static(range(4)):
            u += a[j] * v[ids[j]]
            u0 += a0[j] * v[ids[j]]
        for j in ti.static(range(4)):
            vj = v[ids[j]]
            out[ids[j]] += (a[j] * (cl.penalty[c] @ (u - a[j] * vj))
                            + a0[j] * (cl.damping[c] @ (u0 - a0[j] * vj)))


# -- projective dynamics ---------------------------------------------------------------------
@ti.kernel
def _project_pass(cl: ti.template(), count: ti.i32, x: ti.template(), v: ti.template(),
                  velocity: ti.template(), delta: ti.template(), hits: ti.template()):
    """One Jacobi pass: positions apart to the thickness, or (``velocity``) approaching
    normal velocity removed and tangential velocity cut by Coulomb; each particle moves by
    the mean of its contacts' corrections."""
    prm = ti.static(cl.table.params)
    ti.loop_config(serialize=ti.static(serial(x)))
    for p in range(x.shape[0]):
        delta[p] = ti.Vector.zero(float, 3)
        hits[p] = 0
    ti.loop_config(serialize=ti.static(serial(cl.ids)))
    for c in range(count):
        ids = cl.ids[c]
        alpha, g = cl.gap(ids, cl.kind[c], x)
        d = g.norm()
        w = cl.inverse_mass(ids, alpha)
        if d > 0.0 and d < prm[0] and w > 0.0:
            n = _normal(g, d)
            impulse = ti.Vector.zero(float, 3)
            if ti.static(velocity):
                v_rel = ti.Vector.zero(float, 3)
                for j in ti.static(range(4)):
                    v_rel += alpha[j] * v[ids[j]]
                vn = v_rel.dot(n)
                if vn < 0.0:
                    vt = v_rel - vn * n
                    speed = vt.norm()
                    jn = -vn / w
                    jt = ti.min(prm[2] * jn, speed / w)
                    impulse = jn * n - jt * vt / ti.max(speed, 1e-30)
            else:
                impulse = (prm[0] - d) / w * n
            for j in ti.static(range(4)):
                q = ids[j]
                if cl.inv_mass[q] > 0.0 and alpha[j] != 0.0:
                    delta[q] += cl.inv_mass[q] * alpha[j] * impulse
                    hits[q] += 1
    ti.loop_config(serialize=ti.static(serial(x)))
    for p in range(x.shape[0]):
        if hits[p] > 0:
            if ti.static(velocity):
                v[p] += delta[p] / hits[p]
            else:
                x[p] += delta[p] / hits[p]


@ti.data_oriented
class SelfContact(Term):
    """Self-collision of the scene's cloths and ropes (see the module docstring).

    Attributes:
        table: the model's ``topology.SelfCollisionTable``.
        search: the broad phase (``Search``).
        candidates: the current ``ContactList``; count: its rows in use.
        rebuilds: how many times the candidate list was built.
    """
    name = "self_contact"
    implicit = "potential"
    projective = "projection"
    in_kernel = False          # the list's rebuild test and growth run in Python

    @staticmethod
    def present(model):
        return model.self_collision is not None

    def __init__(self, model):
        table = self.table = model.self_collision
        real = runtime.real()
        self.inv_mass = model.inv_mass
        self._x_ref = ti.Vector.field(3, real, shape=model.particle_count)
        self._centre = ti.Vector.field(3, ti.f64, shape=())
        self._grids = (HashGrid(table.point_count), HashGrid(table.edge_count))
        self.search = self._search(4 * QUERY_BLOCK)
        self.candidates = self._list(8 * (table.point_count + table.edge_count))
        self.count = 0
        self.rebuilds = 0
        self._built = False
        self._x0 = None
        self._scratch = {}

    def _search(self, block_slots):
        return Search(self.table, self.inv_mass, self._grids, self._x_ref, block_slots)

    def _list(self, capacity):
        return ContactList(self.table, self.inv_mass, capacity)

    def _field(self, key, make):
        if key not in self._scratch:
            self._scratch[key] = make()
        return self._scratch[key]

    def update(self, x):
        """Rebuild the candidate list at x when two particles may have moved relative to
        each other by more than the skin since the last build (or on first use)."""
        skin = self.table.settings["skin"]
        if self._built and _relative_displacement(self.search, x, self._centre) <= skin:
            return
        while True:
            count, most = (int(c) for c in _rebuild(self.search, self.candidates, x,
                                                    self._centre))
            if most > self.search.block_slots:
                self.search = self._search(2 * most)
            elif count > self.candidates.capacity:
                self.candidates = self._list(2 * count)
            else:
                break
        self.count, self._built = count, True
        self.rebuilds += 1
        if self._x0 is not None:
            _lag(self.candidates, self.count, self._x0)

    def add_forces(self, x, v, t, f_out):
        self.update(x)
        self_contact_forces(self.candidates, self.count, x, v, f_out)

    def energy(self, x, t, out):
        self.update(x)
        return _energy(self.candidates, self.count, x, out)

    def active(self, x):
        """{"point_triangle": n, "edge_edge": m}: contacts closer than the thickness at x."""
        self.update(x)
        pt, ee = (int(c) for c in _active(self.candidates, self.count, x))
        return {"point_triangle": pt, "edge_edge": ee}

    # -- backward Euler ----------------------------------------------------------------------
    def begin_step(self, x0, t0):
        """The lagged normal forces, normals and weights at the step's start x0 (also after
        every rebuild within the step)."""
        self._x0 = x0
        self._field("diag", lambda: ti.Matrix.field(3, 3, runtime.real(), shape=x0.shape[0]))
        self.update(x0)
        _lag(self.candidates, self.count, x0)

    def add_incremental(self, x, x0, h, with_grad, acc, grad):
        """acc[0] += the contacts' part of E at x (acc[1] its magnitude); with_grad:
        grad += its gradient."""
        self.update(x)
        _incremental(self.candidates, self.count, x, x0, h, with_grad, acc, grad)

    def prepare_blocks(self, x, x0, h):
        """Each particle's diagonal contact block at x, read by ``diagonal_block``."""
        self.update(x)
        _blocks(self.candidates, self.count, x, x0, h, self._scratch["diag"])

    @ti.func
    def diagonal_block(self, p):
        return self._scratch["diag"][p]

    def add_product(self, v, out, first):
        """out += (= when ``first``) the couplings between the contacts' particles (their
        Hessian at the last ``prepare_blocks`` without its diagonal blocks) times v."""
        _couplings(self.candidates, self.count, v, out, first)

    # -- projective dynamics -----------------------------------------------------------------
    def project(self, x, v, t):
        """Jacobi passes moving penetrating contacts apart to the thickness, then one
        removing their approaching normal velocity with Coulomb friction."""
        n = x.shape[0]
        delta = self._field("delta", lambda: ti.Vector.field(3, runtime.real(), shape=n))
        hits = self._field("hits", lambda: ti.field(ti.i32, shape=n))
        self.update(x)
        for _ in range(PROJECTION_PASSES):
            _project_pass(self.candidates, self.count, x, v, False, delta, hits)
        _project_pass(self.candidates, self.count, x, v, True, delta, hits)


