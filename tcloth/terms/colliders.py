"""Colliders (every shape of ``shapes.SHAPES``) with penalty contact and Coulomb friction
(lecture 4).

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

Backward Euler takes the penalty as a potential k/2 depth^2 at the end of the step, and
normal damping and friction with the normal force and normal of the step's start, as a
convex dissipation potential whose gradient is exactly the explicit law at the end
velocity. Projective dynamics projects penetrating particles back onto the offset surface
after its iterations (inelastic normal, Coulomb tangential).

The shapes (signed distance and normal) are in ``shapes.py``. All colliders of a scene
are handled by one kernel launch; shapes the scene lacks are compiled out; a scene
without colliders has no collider term.
"""
import taichi as ti

from .. import runtime
from ..runtime import serial
from .base import Term, particle_energy


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
    speed = vt.norm()
    return fn * n - mu * fn / ti.max(speed, eps) * vt


@ti.func
def add_dissipation(e, g, block, v, n0, fn0, cd, mu, eps, h):
    """(e, g, block) plus backward Euler's normal damping and friction of a contact as convex
    potentials of the end velocity v, with the start of the step's normal n0 and normal
    force fn0 > 0 and the damping coefficient cd: energy, gradient with respect to the
    position, and its Hessian block."""
    vn = v.dot(n0)
    nn = n0.outer_product(n0)
    if vn < 0.0:
        e += 0.5 * cd * h * vn * vn
        g += cd * vn * n0
        block += cd / h * nn
    vt = v - vn * n0
    s = vt.norm()
    tangent = ti.Matrix.identity(float, 3) - nn
    if s < eps:
        e += mu * fn0 * h * s * s / (2.0 * eps)
        g += mu * fn0 / eps * vt
        block += mu * fn0 / (eps * h) * tangent
    else:
        e += mu * fn0 * h * (s - 0.5 * eps)
        g += mu * fn0 / s * vt
        that = vt / s
        block += mu * fn0 / (s * h) * (tangent - that.outer_product(that))
    return e, g, block


@ti.data_oriented
class Colliders(Term):
    """Penalty contact and Coulomb friction against the scene's colliders; skipped for
    pinned particles. Backward Euler: a potential (with lagged friction and damping);
    projective: a projection after the iterations."""
    name = "contact"
    implicit = "potential"
    projective = "projection"
    per_particle = True

    @staticmethod
    def present(model):
        return model.colliders.count > 0

    def __init__(self, model):
        self.table = model.colliders
        self.mass, self.inv_mass = model.mass, model.inv_mass
        self._lagged = None

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
            f = self.table.for_each_contact(x, p, t, self._force_body, f, (v[p], self.mass[p]))
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
            e = self.table.for_each_contact(x, p, t, self._energy_body, e, 0)
        return e

    @ti.func
    def accumulate(self, x, v, t, f_out):
        """f_out += the contact forces of every collider."""
        ti.loop_config(serialize=ti.static(serial(f_out)))
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
        depth = col.thickness - phi
        fn = 0.0
        if depth > 0.0 and self.inv_mass[p] > 0.0:
            fn = col.stiffness * depth
        self._lagged[0][p, c] = fn
        self._lagged[1][p, c] = n
        return 0

    @ti.func
    def begin(self, p, x0, t0):
        self.table.for_each_contact(x0, p, t0, self._begin_body, 0, 0)

    @ti.func
    def _incremental_parts(self, col, c, x, p, phi, n, x0p, h):
        """(energy, gradient, Hessian block) of one contact in the step's incremental
        potential: penalty k/2 depth^2 at x (its block k n n^T without the curvature
        term), normal damping and friction with the start-of-step normal and force as
        convex potentials of the end velocity."""
        depth = col.thickness - phi
        e = 0.0
        g = ti.Vector.zero(float, 3)
        block = ti.Matrix.zero(float, 3, 3)
        k = col.stiffness
        if depth > 0.0:
            e += 0.5 * k * depth * depth
            g -= k * depth * n
            block += k * n.outer_product(n)
        fn0 = self._lagged[0][p, c]
        if fn0 > 0.0:
            cd = 2.0 * col.damping * ti.sqrt(k * self.mass[p])
            e, g, block = add_dissipation(e, g, block, (x[p] - x0p) / h - col.velocity,
                                          self._lagged[1][p, c], fn0, cd, col.friction,
                                          col.stick_velocity, h)
        return e, g, block

    @ti.func
    def _incremental_body(self, col, c, x, p, phi, n, ctx):
        x0p, h = ctx
        e, g, _ = self._incremental_parts(col, c, x, p, phi, n, x0p, h)
        return ti.Vector([e, g[0], g[1], g[2]])

    @ti.func
    def incremental(self, p, x, x0, h, t):
        """(energy, magnitude, gradient) of particle p's contacts in backward Euler's
        incremental potential at positions x; x0 the step's start."""
        eg = ti.Vector.zero(float, 4)
        if self.inv_mass[p] > 0.0:
            eg = self.table.for_each_contact(x, p, t, self._incremental_body, eg, (x0[p], h))
        return eg[0], eg[0], ti.Vector([eg[1], eg[2], eg[3]])

    @ti.func
    def _block_body(self, col, c, x, p, phi, n, ctx):
        x0p, h = ctx
        _, _, block = self._incremental_parts(col, c, x, p, phi, n, x0p, h)
        return block

    @ti.func
    def hessian_block(self, p, x, x0, h, t):
        """The sum of particle p's contact Hessian blocks (zero when pinned)."""
        block = ti.Matrix.zero(float, 3, 3)
        if self.inv_mass[p] > 0.0:
            block = self.table.for_each_contact(x, p, t, self._block_body, block, (x0[p], h))
        return block

    # -- projective dynamics ---------------------------------------------------------------
    @ti.func
    def _project_body(self, col, c, x, p, phi, n, v):
        depth = col.thickness - phi
        if depth > 0.0 and col.stiffness > 0.0:
            x[p] += depth * n
            v_rel = v[p] - col.velocity
            vn = v_rel.dot(n)
            if vn < 0.0:
                vt = v_rel - vn * n
                speed = vt.norm()
                cut = ti.min(col.friction * (-vn), speed)
                vt -= cut * vt / ti.max(speed, 1e-30)
                v[p] = col.velocity + vt
        return 0

    def project(self, x, v, t):
        """Put penetrating particles back on the offset surface; remove their inward normal
        velocity and cut the tangential one by mu times that change (Coulomb), relative to
        the collider's motion."""
        project_contacts(self, x, v, t)


@ti.kernel
def _touching(term: ti.template(), x: ti.template(), t: float) -> ti.i32:
    count = 0
    for p in range(x.shape[0]):
        if term.inv_mass[p] > 0.0:
            if term.table.for_each_contact(x, p, t, term._touch_body, 0, 0) > 0:
                count += 1
    return count


@ti.kernel
def begin_contacts(term: ti.template(), x0: ti.template(), t0: float):
    ti.loop_config(serialize=ti.static(serial(x0)))
    for p in range(x0.shape[0]):
        term.begin(p, x0, t0)


@ti.kernel
def project_contacts(term: ti.template(), x: ti.template(), v: ti.template(), t: float):
    ti.loop_config(serialize=ti.static(serial(x)))
    for p in range(x.shape[0]):
        if term.inv_mass[p] > 0.0:
            term.table.for_each_contact(x, p, t, term._project_body, 0, v)
