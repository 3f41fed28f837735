"""Self-collision: cloths and ropes kept from passing through themselves and each other.

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

Contact set. The term reads the candidates of the simulator's contact stage
(``contact/stage.py``: one list per simulator, rebuilt only at the stage's update points),
never builds one itself, and skips the rows that do not repel (pairs that touch by
construction, listed for the guard); the stage also guards every step's motion
(``contact/guard.py``).

Integrators. Explicit integrators take the force. Backward Euler takes the penalty energy
at the end positions and, like the colliders, the normal damping and friction as convex
dissipation potentials with the start of the step's normal force, normal and weights; the
Newton matrix gets each contact's Gauss-Newton Hessian (the penalty's k n n^T without
the curvature term, which is negative, and the dissipation's blocks) spread over its four
particles: the diagonal blocks in the block-Jacobi preconditioner, the couplings between
them applied matrix-free in CG's products (``add_product``). VBD takes the same gradient
and exact blocks particle by particle inside its sweeps (``vertex_system``: each particle's
rows, indexed at the step's start, evaluated at the current positions), and their energy
(``vertex_energy``) for its line search where a move can bring a row into contact. Projective
dynamics projects after its iterations: Gauss-Seidel passes over the penetrating
contacts moving the particles apart to distance T (an impulse along the contact's
weights, inverse-mass weighted: momentum is kept), then one over the contacts within T
(those left at T included) removing approaching normal velocity and cutting tangential
velocity by mu times that (Coulomb), along the surfaces' normal where it separates the
contact (``normals.contact_normal``: between two layers the closest points' direction of
offset edges tilts along them, and removing approach along it took a sliding cloth's
speed). Each correction can be kept (``ProjectionLog``) for the gradient
(``grad/projected.py``).
"""
import taichi as ti

from .. import runtime
from ..contact.broad import near, spread
from ..contact.normals import contact_normal, sides, vertex_normals
from ..contact.projection import LOG_CAPACITY, ProjectionLog
from ..contact.search import POINT_TRIANGLE
from ..features.self_collision import SELF_COLLISION
from ..runtime import serial
from .base import Term
from .colliders import contact_force
from .contact_lag import (Lagged, lag_rows, penalty_gradient, row_dissipation,
                          unit_normal)
from .vertex_rows import VertexRows

PROJECTION_PASSES = 4
# the velocity pass reaches the thickness times (1 + this): the position passes leave their
# contacts at the thickness, where rounding put about half of them outside it (their
# approaching velocity kept, and a step's outcome split by perturbations of 1e-9)
VELOCITY_REACH = 1e-6


@ti.func
def pair_force(cl, c, x, v):
    """(touches, ids, alpha, f) of candidate c of list cl at (x, v): particle k of the
    contact gets alpha_k f where it touches (a repelling pair closer than the thickness,
    not at d = 0, with a free particle)."""
    prm = ti.static(cl.table.params)
    ids, kind = cl.ids[c], cl.kind[c]
    alpha, g = cl.gap(ids, kind, x)
    d = g.norm()
    thickness, k = prm[0], prm[1]
    touches = False
    f = ti.Vector.zero(float, 3)
    if cl.repels[c] and d > 0.0 and d < thickness:
        n = unit_normal(g, d)
        v_rel = ti.Vector.zero(float, 3)
        for j in ti.static(range(4)):
            v_rel += alpha[j] * v[ids[j]]
        w = cl.inverse_mass(ids, alpha)
        if w > 0.0:
            touches = True
            f = contact_force(thickness - d, v_rel, n, k, 2.0 * prm[3] * ti.sqrt(k / w),
                              prm[2], prm[4])
    return touches, ids, alpha, f


@ti.kernel
def self_contact_forces(
        # Model:
        cl: ti.template(), count: ti.i32, ref_gap: ti.template(),
        # State in:
        x: ti.template(), v: ti.template(), far: ti.template(),
        # Out:
        f_out: ti.template()):
    """f_out += the self-contact forces of the first ``count`` candidates of the
    proximity list (its ``ref_gap``; ``far`` from its ``moved(x)``: the rows that the
    list's bound keeps beyond the thickness are skipped, ``broad.near``)."""
    pair_forces(cl, count, ref_gap, x, v, far, f_out)


@ti.func
def pair_forces(cl, count, ref_gap, x, v, far, f_out):
    """``self_contact_forces`` as a ``ti.func`` (a batch of substeps')."""
    ti.loop_config(serialize=ti.static(serial(cl.ids)))
    for c in range(count):
        if near(cl, ref_gap, far, c, cl.table.params[0]):
            touches, ids, alpha, f = pair_force(cl, c, x, v)
            if touches:
                for j in ti.static(range(4)):
                    f_out[ids[j]] += alpha[j] * f


@ti.kernel
def _energy(cl: ti.template(), count: ti.i32, ref_gap: ti.template(), x: ti.template(),
            far: ti.template(), out: ti.template()) -> ti.f64:
    """The penalty energy of the contacts (the rows skipped as by ``self_contact_forces``)."""
    prm = ti.static(cl.table.params)
    out[0] = 0
    ti.loop_config(serialize=ti.static(serial(cl.ids)))
    for c in range(count):
        if near(cl, ref_gap, far, c, prm[0]):
            alpha, g = cl.gap(cl.ids[c], cl.kind[c], x)
            depth = prm[0] - g.norm()
            if cl.repels[c] and depth > 0.0:
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
        if cl.repels[c] and g.norm() < cl.table.params[0]:
            if kind == POINT_TRIANGLE:
                pt += 1
            else:
                ee += 1
    return ti.Vector([pt, ee])


# -- backward Euler --------------------------------------------------------------------------
@ti.kernel
def _incremental(cl: ti.template(), lag: ti.template(), count: ti.i32, x: ti.template(),
                 x0: ti.template(), h: float, with_grad: ti.template(),
                 acc_out: ti.template(), grad_out: ti.template()):
    """acc_out[0], acc_out[1] += the contacts' part of backward Euler's incremental
    potential; with_grad: grad_out += its gradient."""
    prm = ti.static(cl.table.params)
    ti.loop_config(serialize=ti.static(serial(cl.ids)))
    for c in range(count):
        ids, alpha, depth, grad = penalty_gradient(cl, c, x)
        e = 0.0
        if cl.repels[c] and depth > 0.0:
            e = 0.5 * prm[1] * depth * depth
            if ti.static(with_grad):
                for j in ti.static(range(4)):
                    grad_out[ids[j]] += alpha[j] * grad
        e_d, g_d, _ = row_dissipation(cl, lag, c, x, x0, h, False)
        if ti.static(with_grad):
            alpha0 = lag.alpha0[c]
            for j in ti.static(range(4)):
                grad_out[ids[j]] += alpha0[j] * g_d
        acc_out[0] += ti.cast(e + e_d, acc_out.dtype)
        acc_out[1] += ti.cast(e + e_d, acc_out.dtype)


@ti.kernel
def _blocks(cl: ti.template(), lag: ti.template(), count: ti.i32, x: ti.template(),
            x0: ti.template(), h: float, diag: ti.template()):
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
        if cl.repels[c] and d < prm[0]:
            n = unit_normal(g, d)
            penalty = prm[1] * n.outer_product(n)
        _e, _g, block = row_dissipation(cl, lag, c, x, x0, h, False)
        alpha0 = lag.alpha0[c]
        lag.alpha[c] = alpha
        lag.penalty[c] = penalty
        lag.damping[c] = block
        for j in ti.static(range(4)):
            diag[ids[j]] += alpha[j] * alpha[j] * penalty + alpha0[j] * alpha0[j] * block


@ti.kernel
def _couplings(cl: ti.template(), lag: ti.template(), count: ti.i32, v: ti.template(),
               out: ti.template(), first: ti.template()):
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
        ids, a, a0 = cl.ids[c], lag.alpha[c], lag.alpha0[c]
        u = ti.Vector.zero(float, 3)
        u0 = ti.Vector.zero(float, 3)
        for j in ti.static(range(4)):
            u += a[j] * v[ids[j]]
            u0 += a0[j] * v[ids[j]]
        for j in ti.static(range(4)):
            vj = v[ids[j]]
            out[ids[j]] += (a[j] * (lag.penalty[c] @ (u - a[j] * vj))
                            + a0[j] * (lag.damping[c] @ (u0 - a0[j] * vj)))


# -- projective dynamics ---------------------------------------------------------------------
@ti.func
def projection_impulse(prm, g, n, w, v_rel, velocity: ti.template()):
    """(fires, impulse) of one projection correction of a contact with gap g, inverse
    effective mass w, relative velocity v_rel and unit normal n (g's direction in the
    position passes): where it is closer than the thickness (the velocity pass: within
    VELOCITY_REACH beyond it), the impulse along n that moves it apart to the thickness
    or (``velocity``) removes its approaching velocity along n and cuts the tangential
    by Coulomb; particle k of the contact then moves by alpha_k / m_k times it."""
    d = g.norm()
    reach = prm[0] * (1.0 + VELOCITY_REACH) if ti.static(velocity) else prm[0]
    fires = d > 0.0 and d < reach and w > 0.0
    impulse = ti.Vector.zero(float, 3)
    if fires:
        if ti.static(velocity):
            vn = v_rel.dot(n)
            fires = vn < 0.0
            if fires:
                vt = v_rel - vn * n
                speed = vt.norm()
                jn = -vn / w
                jt = ti.min(prm[2] * jn, speed / w)
                impulse = jn * n - jt * vt / ti.max(speed, 1e-30)
        else:
            impulse = (prm[0] - d) / w * n
    return fires, impulse


@ti.kernel
def _vertex_normals(table: ti.template(), x: ti.template()):
    vertex_normals(table, x, table.normals)


@ti.kernel
def _project_pass(cl: ti.template(), count: ti.i32, x: ti.template(), v: ti.template(),
                  velocity: ti.template(), log: ti.template()):
    """One Gauss-Seidel pass over the contacts (on one thread, in list order): positions
    apart to the thickness, or (``velocity``) approaching velocity removed and
    tangential velocity cut by Coulomb along the contact's normal (``projection_impulse``;
    the normal ``normals.contact_normal`` chooses, from the vertex normals in
    ``cl.table.normals``). Each correction is an impulse along the contact's weights,
    alpha_k / m_k on particle k: equal and opposite, so momentum is kept. ``log`` keeps
    each correction (where on), its kind plus the normal's choice."""
    prm = ti.static(cl.table.params)
    ti.loop_config(serialize=True)
    for c in range(count):
        ids, kind = cl.ids[c], cl.kind[c]
        alpha, g = cl.gap(ids, kind, x)
        a, b = sides(ids, cl.table.normals)
        n, choice = unit_normal(g, g.norm()), 0
        v_rel = ti.Vector.zero(float, 3)
        if ti.static(velocity):
            n, choice = contact_normal(ids, kind, x, cl.table.normals, g, prm[0])
            for j in ti.static(range(4)):
                v_rel += alpha[j] * v[ids[j]]
        if cl.repels[c]:
            fires, impulse = projection_impulse(prm, g, n, cl.inverse_mass(ids, alpha),
                                                v_rel, velocity)
            if fires:
                log.keep(ids, kind + choice, int(velocity), x, v, a, b)
                for j in ti.static(range(4)):
                    q = ids[j]
                    if ti.static(velocity):
                        v[q] += cl.inv_mass[q] * alpha[j] * impulse
                    else:
                        x[q] += cl.inv_mass[q] * alpha[j] * impulse


@ti.data_oriented
class SelfContact(Term):
    """Self-collision of the scene's cloths and ropes (see the module docstring), over the
    candidates of the simulator's contact stage.

    Attributes:
        table: the model's ``contact.topology.SelfCollisionTable``.
        stage: the simulator's ``contact.ContactStage`` (``Simulator.contact``).
    """
    name = "self_contact"
    feature = SELF_COLLISION
    implicit = "potential"
    projective = "projection"
    provides = frozenset({"couplings", "projection", "vertex_system"})
    in_kernel = False          # its list is the stage's, which Python grows and rebuilds
    in_batch = True            # a batch stops where the stage needs Python (batch.py)
    # per_vertex: built for VBD, whose sweeps evaluate each particle's rows
    # (``vertex_system``) from an index made at each step's start
    options = {"per_vertex": False}
    reads_contact = True

    @staticmethod
    def present(model):
        return model.self_collision is not None

    def __init__(self, model, contact, per_vertex=False):
        self.table = model.self_collision
        self.stage = contact
        self.inv_mass = model.inv_mass
        self._scratch = {}
        self.lag = None             # ``Lagged``, as long as the stage's list at least
        self.log = ProjectionLog(1)     # its full size once ``record`` is on
        # VBD's: each particle's rows of the list, indexed at each step's start
        self.rows = VertexRows(model.particle_count) if per_vertex else None

    def _field(self, key, make):
        if key not in self._scratch:
            self._scratch[key] = make()
        return self._scratch[key]

    def add_forces(self, x, v, t, f_out):
        broad = self.stage.broad
        broad.moved(x)
        self_contact_forces(broad.candidates, broad.count, broad.ref_gap, x, v, broad.far,
                            f_out)

    @ti.func
    def accumulate(self, x, v, t, f_out):
        """``add_forces`` as a ``ti.func`` for a batch of substeps: the proximity list as
        it was when the batch compiled (``ContactStage.batch_key``), its rows in use and
        the particles' motion since its build read when it runs."""
        spread(self.stage.broad, self.stage.broad.x_ref, x, x, False)
        pair_forces(self.stage.broad.candidates, self.stage.broad.rows[None],
                    self.stage.broad.ref_gap, x, v, self.stage.broad.far, f_out)

    def energy(self, x, t, out):
        broad = self.stage.broad
        broad.moved(x)
        return _energy(broad.candidates, broad.count, broad.ref_gap, x, broad.far, out)

    def active(self, x):
        """{"point_triangle": n, "edge_edge": m}: contacts closer than the thickness at x."""
        pt, ee = (int(c) for c in _active(self.stage.candidates, self.stage.count, x))
        return {"point_triangle": pt, "edge_edge": ee}

    # -- backward Euler ----------------------------------------------------------------------
    def begin_step(self, x0, t0):
        """The lagged normal forces, normals and weights at the step's start x0."""
        self._field("diag", lambda: ti.Matrix.field(3, 3, runtime.real(), shape=x0.shape[0]))
        cl = self.stage.candidates
        if self.lag is None or self.lag.capacity < cl.capacity:    # the list grew
            self.lag = Lagged(cl.capacity)
        lag_rows(cl, self.lag, self.stage.count, x0)
        if self.rows is not None:
            self.rows.index(cl, self.stage.count, self.lag)

    def layout(self):
        """An int that changes where the fields ``vertex_system`` reads were made again
        (a kernel that calls it compiles again)."""
        return self.rows.layout

    @ti.func
    def vertex_system(self, p, x, x0, h):
        """(gradient, Hessian block, clearance) of particle p at x from its rows of the
        list, each evaluated afresh (VBD's sweeps: its partners moved since):
        ``VertexRows.system``'s."""
        return self.rows.system(p, x, x0, h)

    @ti.func
    def vertex_energy(self, p, x, x0, h):
        """The contacts' part of E at x as a function of x[p] alone, up to a constant
        (VBD's line search): ``VertexRows.energy``."""
        return self.rows.energy(p, x, x0, h)

    def add_incremental(self, x, x0, h, with_grad, acc, grad):
        """acc[0] += the contacts' part of E at x (acc[1] its magnitude); with_grad:
        grad += its gradient."""
        _incremental(self.stage.candidates, self.lag, self.stage.count, x, x0, h, with_grad,
                     acc, grad)

    def prepare_blocks(self, x, x0, h):
        """Each particle's diagonal contact block at x, read by ``diagonal_block``."""
        _blocks(self.stage.candidates, self.lag, self.stage.count, x, x0, h,
                self._scratch["diag"])

    @ti.func
    def diagonal_block(self, p):
        return self._scratch["diag"][p]

    def add_product(self, v, out, first):
        """out += (= when ``first``) the couplings between the contacts' particles (their
        Hessian at the last ``prepare_blocks`` without its diagonal blocks) times v."""
        _couplings(self.stage.candidates, self.lag, self.stage.count, v, out, first)

    # -- projective dynamics -----------------------------------------------------------------
    def project(self, x, v, t):
        """Gauss-Seidel passes moving penetrating contacts apart to the thickness, then one
        removing their approaching normal velocity with Coulomb friction (momentum kept),
        along the normals ``contact_normal`` chooses with the vertex normals at x."""
        cl, count = self.stage.candidates, self.stage.count
        self.log.count[None] = 0
        _vertex_normals(self.table, x)
        for _ in range(PROJECTION_PASSES):
            _project_pass(cl, count, x, v, False, self.log)
        _project_pass(cl, count, x, v, True, self.log)

    def record(self, on):
        """Keep the projection's corrections of each step (``log``) from now on (``on``),
        for a gradient (``tcloth/grad/projected.py``)."""
        if on and self.log.capacity < LOG_CAPACITY:
            self.log = ProjectionLog(LOG_CAPACITY)
        self.log.on[None] = int(on)
