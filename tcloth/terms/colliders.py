"""Colliders (every shape of ``shapes.SHAPES``) with penalty contact and Coulomb friction.

Detection: the signed distance phi(x) to each shape and its outward unit normal n.
Resolution: a particle closer than the collider's ``thickness`` is pulled by a temporary
zero-rest-length spring of stiffness k to the closest surface point pushed out by the
thickness: f_n = k (thickness - phi) n, minus a normal damping 2 zeta sqrt(k m) v_n
(zeta = ``damping``, a ratio of critical; the total is clamped to push only). Friction
opposes the tangential velocity relative to the collider, |f_t| <= mu |f_n|:

    f_t = -mu |f_n| v_t / max(|v_t|, eps),   eps = ``stick_velocity`` (m/s).

Below eps the friction is a viscous regularisation of sticking: a particle held by static
friction on an incline creeps at eps tan(theta) / mu. For explicit integrators keep
eps > mu g dt / 2 so that the regularised stick regime is itself stable.

The implicit and frame-rate solvers take the contact inside their solve, against a plane
per particle and collider linearised at the step's start (``begin_solve``): its depth is
the thickness less the particle's height above that plane, so that a cloth landing on a
collider is held by it through the solve, and a step cannot take it through a thin one.
Backward Euler takes the penalty as a potential k/2 depth^2 at the end of the step, and
normal damping and friction with the normal force and normal of the step's start, as a
convex dissipation potential whose gradient is exactly the explicit law at the end
velocity; VBD likewise, with friction's block a majorant's (``add_dissipation``).
Projective dynamics has the penalty and normal damping in its residual, the approach
speed the damping sees capped at depth / h so that the force is continuous where contact
begins (``plane_contact_force``), and their stiffness in its matrix along the normals
(``plane_force``, ``plane_stiffness``), XPBD pushes particles out (``push_out``), and
both apply friction after the solve with the normal velocity change it gave
(``plane_coulomb``).

The shapes (signed distance and normal) are in ``shapes.py``. All colliders of a scene
are handled by one kernel launch; shapes the scene lacks are compiled out; a scene
without colliders has no collider term.
"""
import taichi as ti

from .. import runtime
from ..geometry.meshstore import QUERY_WORK
from ..runtime import serial
from .base import Term, norm_above, particle_energy

NO_PLANE = -1e30     # a contact plane's offset where a particle has none (``plane_offset``)


@ti.func
def contact_force(depth, v_rel, n, k, cd, mu, eps):
    """The contact law at penetration depth > 0 along the unit normal n, for the relative
    velocity v_rel against the surface: f_n = max(k depth - cd v_n, 0) along n plus Coulomb
    friction -mu f_n v_t / max(|v_t|, eps), with the damping coefficient cd = 2 zeta
    sqrt(k m) for the damping ratio zeta and the effective mass m. Self-contact uses it
    between two moving surfaces."""
    vn = v_rel.dot(n)
    fn = ti.max(k * depth - cd * vn, 0.0)
    vt = v_rel - vn * n
    return fn * n - mu * fn / norm_above(vt, eps) * vt


@ti.func
def add_dissipation(e, g, block, v, n0, fn0, cd, mu, eps, h, majorant: ti.template()):
    """(e, g, block) plus backward Euler's normal damping and friction of a contact as convex
    potentials of the end velocity v, with the start of the step's normal n0 and normal
    force fn0 > 0 and the damping coefficient cd: energy, gradient with respect to the
    position, and its Hessian block.

    Sliding (|v_t| = s >= eps), friction's potential mu fn0 h (s - eps/2) is a cone: its
    Hessian has no curvature along the sliding direction, where its gradient is mu fn0
    whatever the speed. With ``majorant`` the block is instead the Hessian of the
    quadratic in v_t that touches the cone at v_t and lies above it elsewhere,
    mu fn0 / (s h) times the whole tangent projector (the same formula as sticking's with
    s for eps, so continuous at s = eps): a Newton step on one vertex then stops short of
    reversing its sliding (``vbd.py``)."""
    vn = v.dot(n0)
    nn = n0.outer_product(n0)
    if vn < 0.0:
        e += 0.5 * cd * h * vn * vn
        g += cd * vn * n0
        block += cd / h * nn
    vt = v - vn * n0
    s2 = vt.dot(vt)
    tangent = ti.Matrix.identity(float, 3) - nn
    if s2 < eps * eps:      # (the norm's derivative at rest is 0/0: reverse mode)
        e += mu * fn0 * h * s2 / (2.0 * eps)
        g += mu * fn0 / eps * vt
        block += mu * fn0 / (eps * h) * tangent
    else:
        s = ti.sqrt(s2)
        e += mu * fn0 * h * (s - 0.5 * eps)
        g += mu * fn0 / s * vt
        if ti.static(majorant):
            block += mu * fn0 / (s * h) * tangent
        else:
            that = vt / s
            block += mu * fn0 / (s * h) * (tangent - that.outer_product(that))
    return e, g, block


@ti.func
def plane_offset(col, x0p, phi, n, v0p, h, fall, free):
    """Backward Euler's contact plane of a particle at x0p (signed distance phi, outward
    normal n, velocity v0p) with a collider for a step of h (``Colliders.begin_solve``):
    the offset b of the tangent plane n . x = b at its closest point, moved with the
    collider over the step, where the particle can reach the collider within the step
    (fall: h^2 |g|), else -1e30 (no plane)."""
    b = NO_PLANE
    reach = h * (v0p.norm() + col.velocity.norm()) + fall + col.thickness
    if col.stiffness > 0.0 and free and phi < col.thickness + reach:
        b = n.dot(x0p - phi * n + h * col.velocity)
    return b


@ti.func
def lagged_normal_force(col, phi, free):
    """The penalty's normal force k (thickness - phi) at a step's start (0 where the
    particle is pinned or not within the thickness): friction's bound in the step."""
    fn = 0.0
    if col.thickness - phi > 0.0 and free:
        fn = col.stiffness * (col.thickness - phi)
    return fn


@ti.func
def step_contact(col, gap, n, xp, x0p, h, m, fn0, n0, majorant: ti.template()):
    """(energy, gradient, Hessian block) of one contact in backward Euler's incremental
    potential at xp (mass m; x0p the step's start): penalty k/2 depth^2 against the
    particle's plane of the step's start (depth = thickness - gap, gap its height above
    the plane of normal n), its block k n n^T, normal damping and friction with the
    start-of-step normal n0 and normal force fn0 as convex potentials of the end
    velocity (friction's block its majorant's with ``majorant``: ``add_dissipation``)."""
    depth = col.thickness - gap
    e = 0.0
    g = ti.Vector.zero(float, 3)
    block = ti.Matrix.zero(float, 3, 3)
    k = col.stiffness
    if depth > 0.0:
        e += 0.5 * k * depth * depth
        g -= k * depth * n
        block += k * n.outer_product(n)
    if fn0 > 0.0:
        cd = 2.0 * col.damping * ti.sqrt(k * m)
        e, g, block = add_dissipation(e, g, block, (xp - x0p) / h - col.velocity,
                                      n0, fn0, cd, col.friction,
                                      col.stick_velocity, h, majorant)
    return e, g, block


@ti.func
def plane_contact_force(col, gap, n, vp, m, h):
    """The penalty and normal damping of a particle (mass m, velocity vp) at height gap
    above its contact plane of normal n (projective dynamics' contact, without friction):
    max(k depth - c_d max(v_n, -depth / h), 0) n where depth = thickness - gap > 0.

    The approach speed the damping sees is at most depth / h: a particle that reached
    depth in a step of length h at the approach speed |v_n| spent the fraction
    depth / (h |v_n|) of it in contact, so the step's damping impulse is c_d depth, not
    c_d |v_n| h. Without that cap the force jumped from 0 to c_d |v_n| as the iterate
    crossed the offset surface, the step had no fixed point, and Liu's iterations cycled
    across it (a cloth thrown at 1 m/s onto a plane at dt 2e-3: a residual of 77 after
    100 iterations where the other steps reached 1e-12; 3e-8 with the cap)."""
    f = ti.Vector.zero(float, 3)
    depth = col.thickness - gap
    if depth > 0.0:
        k = col.stiffness
        cd = 2.0 * col.damping * ti.sqrt(k * m)
        vn = ti.max((vp - col.velocity).dot(n), -depth / h)
        f = ti.max(k * depth - cd * vn, 0.0) * n
    return f


@ti.func
def coulomb_change(col, gap, n, vp, dvn):
    """The velocity change of a particle touching its contact plane (gap within the
    thickness) after a solve that changed its normal velocity by dvn: its approaching
    normal velocity removed, its tangential velocity cut by mu (dvn + that removal), at
    most to rest (Coulomb's bound on the friction impulse)."""
    change = ti.Vector.zero(float, 3)
    if gap <= col.thickness * (1.0 + 1e-3):
        v_rel = vp - col.velocity
        vn = v_rel.dot(n)
        vt = v_rel - vn * n
        change = -ti.min(vn, 0.0) * n
        s2 = vt.dot(vt)
        if s2 > 0.0:        # (a sliding particle: the norm's derivative exists)
            speed = ti.sqrt(s2)
            cut = ti.min(col.friction * (dvn + ti.max(-vn, 0.0)), speed)
            change -= cut * vt / speed
    return change


@ti.data_oriented
class Colliders(Term):
    """Penalty contact and Coulomb friction against the scene's colliders; skipped for
    pinned particles. Backward Euler and VBD: a potential (with lagged friction and
    damping); projective dynamics and XPBD: "contact", which they take inside their
    iterations themselves."""
    name = "contact"
    implicit = "potential"
    projective = "contact"
    per_particle = True
    provides = frozenset({"contact_planes"})
    # friction_majorant: built for VBD, whose Newton step on one vertex takes friction's
    # block as its majorant's (``add_dissipation``)
    options = {"friction_majorant": False}

    @staticmethod
    def present(model):
        return model.colliders.count > 0

    def __init__(self, model, friction_majorant=False):
        self.majorant = friction_majorant
        self.table = model.colliders
        self.mass, self.inv_mass, self.params = model.mass, model.inv_mass, model.params
        # a mesh collider's contact is a query of its hierarchy (``runtime.serial``)
        self.work = QUERY_WORK if self.table.meshes is not None else 1
        self._lagged = None
        # (normal, offset, the surface's velocity) per particle and collider: ``begin_solve``
        shape = (model.particle_count, max(self.table.count, 1))
        self._planes = (ti.Vector.field(3, runtime.real(), shape=shape),
                        ti.field(runtime.real(), shape=shape),
                        ti.Vector.field(3, runtime.real(), shape=shape))
        self._h = ti.field(runtime.real(), shape=())     # the planes' step

    # -- explicit force and energy ---------------------------------------------------------
    @ti.func
    def _force_body(self, col, c, x, p, phi, n, ctx):
        v, m = ctx
        f = ti.Vector([0.0, 0.0, 0.0])
        depth = col.thickness - phi
        if depth > 0.0:
            k = col.stiffness
            f = contact_force(depth, v - col.velocity, n, k, 2.0 * col.damping * ti.sqrt(k * m),
                              col.friction, col.stick_velocity)
        return f

    @ti.func
    def force(self, p, x, v, t):
        """The contact force on particle p at (x, v) and time t."""
        f = ti.Vector.zero(float, 3)
        if self.inv_mass[p] > 0.0:
            f = self.table.for_each_contact(x, p, t, self._force_body, f, (v[p], self.mass[p]),
                                            0.0)
        return f

    @ti.func
    def _energy_body(self, col, c, x, p, phi, n, ctx):
        depth = col.thickness - phi
        e = 0.0
        if depth > 0.0:
            e = 0.5 * col.stiffness * depth * depth
        return e

    @ti.func
    def potential(self, p, x, t):
        """k/2 (thickness - phi)^2 summed over the colliders particle p penetrates, J."""
        e = 0.0
        if self.inv_mass[p] > 0.0:
            e = self.table.for_each_contact(x, p, t, self._energy_body, e, 0, 0.0)
        return e

    @ti.func
    def accumulate(self, x, v, t, f_out):
        """f_out += the contact forces of every collider."""
        ti.loop_config(serialize=ti.static(serial(f_out, self.work)))
        for p in range(f_out.shape[0]):
            f_out[p] += self.force(p, x, v, t)

    def energy(self, x, t, out):
        return particle_energy(self, x, t, out)

    @ti.func
    def _touch_body(self, col, c, x, p, phi, n, ctx):
        return 1 if phi < col.thickness and col.stiffness > 0.0 else 0

    def touching(self, x, t):
        """How many particles are within a collider's thickness at x and time t."""
        return int(_touching(self, x, t))

    # -- backward Euler ----------------------------------------------------------------------
    def begin_step(self, x0, t0):
        """Store each contact's normal force and normal at the step's start."""
        if self._lagged is None:
            real, shape = runtime.real(), (x0.shape[0], self.table.count)
            self._lagged = (ti.field(real, shape=shape), ti.Vector.field(3, real, shape=shape))
        begin_contacts(self, x0, t0)

    @ti.func
    def _begin_body(self, col, c, x, p, phi, n, ctx):
        self._lagged[0][p, c] = lagged_normal_force(col, phi, self.inv_mass[p] > 0.0)
        self._lagged[1][p, c] = n
        return 0

    @ti.func
    def begin(self, p, x0, t0):
        self.table.for_each_contact(x0, p, t0, self._begin_body, 0, 0, 0.0)

    @ti.func
    def _incremental_parts(self, col, c, gap, n, ctx):
        """``step_contact`` of particle p's contact with collider c (ctx: (x[p], x0[p], h,
        p)), with the normal force and normal of the step's start (``begin_step``)."""
        xp, x0p, h, p = ctx
        return step_contact(col, gap, n, xp, x0p, h, self.mass[p], self._lagged[0][p, c],
                            self._lagged[1][p, c], self.majorant)

    @ti.func
    def _incremental_body(self, col, c, gap, n, ctx):
        e, g, _ = self._incremental_parts(col, c, gap, n, ctx)
        return ti.Vector([e, g[0], g[1], g[2]])

    @ti.func
    def incremental(self, p, x, x0, h, t):
        """(energy, magnitude, gradient) of particle p's contacts in backward Euler's
        incremental potential at positions x; x0 the step's start."""
        eg = ti.Vector.zero(float, 4)
        if self.inv_mass[p] > 0.0:
            eg = self._for_each_plane(p, x, self._incremental_body, eg, (x[p], x0[p], h, p))
        return eg[0], eg[0], ti.Vector([eg[1], eg[2], eg[3]])

    @ti.func
    def _block_body(self, col, c, gap, n, ctx):
        _e, _g, block = self._incremental_parts(col, c, gap, n, ctx)
        return block

    @ti.func
    def hessian_block(self, p, x, x0, h, t):
        """The sum of particle p's contact Hessian blocks (zero when pinned)."""
        block = ti.Matrix.zero(float, 3, 3)
        if self.inv_mass[p] > 0.0:
            block = self._for_each_plane(p, x, self._block_body, block, (x[p], x0[p], h, p))
        return block

    # -- the step's contact planes (every implicit and frame-rate solver) --------------------
    def begin_solve(self, x0, v0, h, t0):
        """At the start of a step of h from (x0, v0) at t0, each free particle's contact
        plane with each collider it can reach in the step (its distance less h (|v0| + the
        collider's speed) + h^2 |g| and a thickness, below the thickness): the tangent
        plane at its closest point on the surface, normal n0 there, placed where the
        collider is at the step's end. The solvers keep the particle on its outer side,
        offset by the thickness, through their iterations: backward Euler and VBD by the
        penalty against it, projective dynamics in its residual and matrix, XPBD by
        pushing. A linearisation at the step's start, as Newton's planar contact: an
        iterate that lands deep inside a curved collider is pushed back the way it came
        rather than along the radius at the deep point (which spreads a landing cloth
        apart), and one that a step would take through a thin collider is held on the
        side it came from (the shape's own distance at such an iterate points out of the
        far side)."""
        _begin_planes(self, x0, v0, h, t0)

    @ti.func
    def set_planes(self, x0, v0, h, t0):
        """``begin_solve`` as a ``ti.func``."""
        self._h[None] = h
        g = ti.Vector([self.params[0], self.params[1], self.params[2]])
        ti.loop_config(serialize=ti.static(serial(x0, self.work)))
        speed, thick = self.table.bounds[0], self.table.bounds[1]
        for p in range(x0.shape[0]):
            # the farthest _plane_body looks: searched no farther
            beyond = h * (v0[p].norm() + speed) + h * h * g.norm() + thick
            self.table.for_each_contact(x0, p, t0, self._plane_body, 0,
                                        (v0[p], h, h * h * g.norm()), beyond, True)

    @ti.func
    def _plane_body(self, col, c, x0, p, phi, n, ctx):
        v0, h, fall = ctx
        self._planes[0][p, c] = n
        self._planes[1][p, c] = plane_offset(col, x0[p], phi, n, v0, h, fall,
                                             self.inv_mass[p] > 0.0)
        self._planes[2][p, c] = col.velocity
        return 0

    @ti.func
    def reaches(self, p):
        """Whether particle p has a contact plane this step (``begin_solve``): a collider
        it can reach within the step."""
        near = False
        for c in range(self.table.count):
            if self._planes[1][p, c] > 0.5 * NO_PLANE:
                near = True
        return near

    @ti.func
    def _for_each_plane(self, p, x, body: ti.template(), zero, ctx):
        """The sum over colliders c of ``body(col, c, gap, n, ctx)``, gap the height of x[p]
        above collider c's plane (``begin_solve``; huge where it has none), col.velocity
        the surface's velocity at the plane's point."""
        acc = zero
        for c in range(self.table.count):
            n = self._planes[0][p, c]
            col = self.table.data[c]
            col.velocity = self._planes[2][p, c]
            acc += body(col, c, n.dot(x[p]) - self._planes[1][p, c], n, ctx)
        return acc

    @ti.func
    def _plane_force_body(self, col, c, gap, n, ctx):
        vp, m = ctx
        return plane_contact_force(col, gap, n, vp, m, self._h[None])

    @ti.func
    def plane_force(self, p, x, v):
        """The contact law's penalty and normal damping against particle p's planes at
        (x, v[p]), without friction (``plane_coulomb`` applies it after the solve)."""
        return self._for_each_plane(p, x, self._plane_force_body, ti.Vector.zero(float, 3),
                                    (v[p], self.mass[p]))

    @ti.func
    def _stiffness_body(self, col, c, gap, n, m):
        w = 0.0
        if gap < col.thickness:
            w = col.stiffness + 2.0 * col.damping * ti.sqrt(col.stiffness * m) / self._h[None]
        return w * n.outer_product(n)

    @ti.func
    def plane_stiffness(self, p, x):
        """(k + c_d / h) n n^T summed over particle p's planes it is within the thickness
        of at x: the stiffness of its active contacts, along their normals only (the
        penalty and the normal damping act along n), for projective's matrix at an
        iterate."""
        return self._for_each_plane(p, x, self._stiffness_body, ti.Matrix.zero(float, 3, 3),
                                    self.mass[p])

    @ti.func
    def _push_body(self, col, c, gap, n, x):
        return ti.max(col.thickness - gap, 0.0) * n

    @ti.func
    def push_out(self, p, x):
        """Particle p back onto the outer side of its planes, offset by the thickness (a
        hard contact constraint, XPBD's); returns the distance moved (m)."""
        move = self._for_each_plane(p, x, self._push_body, ti.Vector.zero(float, 3), 0)
        x[p] += move
        return move.norm()

    @ti.func
    def _coulomb_body(self, col, c, gap, n, ctx):
        vp, dvn = ctx
        return coulomb_change(col, gap, n, vp, dvn)

    @ti.func
    def plane_coulomb(self, p, x, v, dvn):
        """After a solve whose contact changed particle p's normal velocity by dvn (m/s):
        at each of its planes it touches at x, its approaching normal velocity removed
        and its tangential velocity, relative to the collider, cut by mu times the normal
        velocity change (Coulomb's bound on the friction impulse)."""
        v[p] += self._for_each_plane(p, x, self._coulomb_body, ti.Vector.zero(float, 3),
                                     (v[p], dvn))


@ti.kernel
def _touching(term: ti.template(), x: ti.template(), t: float) -> ti.i32:
    count = 0
    ti.loop_config(serialize=ti.static(serial(x, term.work)))
    for p in range(x.shape[0]):
        if term.inv_mass[p] > 0.0:
            if term.table.for_each_contact(x, p, t, term._touch_body, 0, 0, 0.0) > 0:
                count += 1
    return count


@ti.kernel
def begin_contacts(term: ti.template(), x0: ti.template(), t0: float):
    ti.loop_config(serialize=ti.static(serial(x0, term.work)))
    for p in range(x0.shape[0]):
        term.begin(p, x0, t0)


@ti.kernel
def _begin_planes(term: ti.template(), x0: ti.template(), v0: ti.template(), h: float,
                  t0: float):
    term.set_planes(x0, v0, h, t0)
