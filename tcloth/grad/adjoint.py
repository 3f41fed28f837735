"""The vector-Jacobian products of one step: Taichi's reverse mode over the terms' own
``ti.func``s, on copies of the model's parameters that carry gradients.

``StepAdjoint(model, implicit, projective)`` holds those copies (gravity and drag, the
masses, each spring's stiffness and damping, the colliders' table) and the step's inputs
x, v (and, implicit, the end positions x1), all with gradients, and one differentiable
kernel:

  - explicit (symplectic Euler): the force f(x, v) of gravity and drag, the springs and
    the colliders (``GravityDrag.force``, ``springs.spring_force``, ``Colliders.force``:
    the functions the simulator's kernels call);
  - implicit (backward Euler): the gradient g(x1; x, v) of the step's incremental potential
    (``integrators/potential.py``) over the same terms: inertia M (x1 - x - h v) / h^2,
    gravity and drag (``GravityDrag.incremental``), the springs (``springs.incremental``)
    and the colliders (``colliders.step_contact``), with what the solver fixes at the
    step's start (each spring's damping direction d0, each contact's plane and normal
    force: ``colliders.plane_offset``, ``lagged_normal_force``) computed from x in the same
    kernel, so that their dependence on the step's start is differentiated too;
  - projective (implicit and projective): the force residual G(x1; x, v) whose zero is
    projective dynamics' converged step (``integrators/projective.py``): M/h^2 (x1 - x -
    h v) less the forces at (x1, v1 = (x1 - x) / h) (gravity and drag, the springs with
    their axial damping along the current direction, hinges, membrane), the wind at the
    step's start, and the colliders' penalty and normal damping against each particle's
    plane of the step's start (``plane_contact_force``); and, in a second kernel, the
    Coulomb friction the solver applies to v1 after its iterations (``coulomb_change``).

Self-contact (symplectic and backward Euler): the kernels sum the contact force, or its
part of the incremental potential's gradient, over the rows of ``set_contacts`` (the
list the forward step read, ``frozen.py``) with the term's own functions
(``self_contact.pair_force``; ``lagged``, ``penalty_gradient`` and ``dissipation``, the
lagged values computed from x in the kernel). ``plane_vjp`` differentiates the guard's
planes (``normals.chosen_margin``) at the step's start.

``vjp(seed)`` runs the kernel's reverse mode with ``seed`` as the output's adjoint: the
inputs' gradients (x.grad, v.grad, x1.grad) are set and the parameters' accumulate (a
trajectory's sum over its steps). Which scenes it covers is ``unsupported(scene)``'s
answer; the simulator's own term for a scene it covers is tested against
this kernel to the last digit (tests/test_grad.py).
"""
from types import SimpleNamespace

import numpy as np
import taichi as ti

from .. import runtime
from ..contact.candidates import ContactList
from ..contact.normals import chosen_margin, logged_kind, vertex_normals
from ..contact.projection import LOG_CAPACITY
from ..model.collider_table import ColliderTable
from ..features import FEATURES
from ..terms import Bending, Colliders, GravityDrag, Membrane, Wind
from ..terms.colliders import (coulomb_change, lagged_normal_force, plane_contact_force,
                               plane_offset, step_contact)
from ..terms.contact_lag import dissipation, lagged, penalty_gradient
from ..terms.self_contact import pair_force
from ..terms.springs import direction, incremental, spring_force


# the scene features the adjoint takes (self-collision: symplectic and backward Euler)
COVERED = ("bending", "membrane", "wind", "self_collision")


def unsupported(scene):
    """Why the adjoint cannot take a step of this scene (one line), or None. It covers
    gravity, drag, springs, hinge bending, the membrane, wind, self-collision and the
    analytic colliders at rest."""
    features = [f.name for f in FEATURES if getattr(scene, f.name) is not None
                and f.name not in COVERED]
    if scene.wind is not None and scene.wind["callable"] is not None:
        return "a callable gust is not differentiated (give the wind a sinusoidal gust)"
    if features:
        return f"{', '.join(features)} {'is' if len(features) == 1 else 'are'} not " \
               "differentiated yet (the scene sets it)"
    if scene.welds:
        return "welded seams are not differentiated (Scene.sew(..., weld=True): a weld " \
               "is a merge at a step's end; sew without weld)"
    for i, c in enumerate(scene.colliders):
        if c["kind"] == "mesh":
            return f"mesh colliders are not differentiated yet (collider {i})"
        if np.any(np.asarray(c["velocity"]) != 0.0) or np.any(np.asarray(
                c.get("spin", 0.0)) != 0.0):
            return f"moving colliders are not differentiated yet (collider {i} moves)"
    return None


@ti.data_oriented
class StepAdjoint:
    """One step's differentiable kernel over the model's terms (see the module).

    Attributes (fields with gradients): params (g_x, g_y, g_z, air_drag), drag (each
    particle's drag coefficient), mass, inv_mass (each particle's; the gradient of a mass
    is mass's plus inv_mass's times -1/m^2), ks, kd (each spring's, in the model's spring
    order), table (the colliders', or None), x, v, x1 (the step's inputs), out (its
    output: the force, or the incremental potential's gradient).
    """

    def __init__(self, model, implicit, projective=False):
        real, n = runtime.real(), model.particle_count
        self.model, self.implicit, self.projective = model, implicit, projective
        self.count = model.spring_count
        self.params = ti.field(real, shape=4, needs_grad=True)
        self.drag, self.mass, self.inv_mass = (ti.field(real, shape=n, needs_grad=True)
                                               for _ in range(3))
        self.ks, self.kd = (ti.field(real, shape=max(self.count, 1), needs_grad=True)
                            for _ in range(2))
        self.x, self.v, self.x1, self.v1, self.out = (
            ti.Vector.field(3, real, shape=n, needs_grad=True) for _ in range(5))
        # the kernels' time, read inside their loops (Taichi's reverse mode takes no
        # statement outside a loop, and a ti.func's scalar argument is one)
        self.clock = ti.field(real, shape=3)       # (the time t, the step's start, h)
        self.table = None
        if model.colliders.count:
            self.table = ColliderTable(model.scene.colliders, differentiable=True)
        # backward Euler's contact planes: v again, without gradients (their reach reads
        # |v|, a test with no derivative; |v|'s would be 0/0 at rest)
        self.v_reach = (ti.Vector.field(3, real, shape=n)
                        if self.table is not None and implicit else None)
        view = SimpleNamespace(mass=self.mass, inv_mass=self.inv_mass, params=self.params,
                               drag=self.drag, colliders=self.table, particle_count=n)
        self.gravity = GravityDrag(view)
        self.colliders = Colliders(view) if self.table is not None else None
        self.has_colliders = self.colliders is not None
        self.pairs, self.rest = model.spring_pairs, model.spring_rest
        # self-collision: the contacts of the step (``set_contacts``), the forward run's
        self.self_contact = model.self_collision is not None
        self.rows = ContactList(model.self_collision, self.inv_mass, 1)
        # the guard's planes (``plane_vjp``): each correction's candidate and the adjoints
        # of its normal and delta
        if self.self_contact:
            self.planes = ContactList(model.self_collision, self.inv_mass, LOG_CAPACITY)
            self.n_bar = ti.Vector.field(3, real, shape=LOG_CAPACITY)
            self.delta_bar = ti.field(real, shape=LOG_CAPACITY)
            self.plane_sum = ti.field(real, shape=(), needs_grad=True)
            self.normals = ti.Vector.field(3, real, shape=n, needs_grad=True)
        self.parameter_fields = [self.params, self.drag, self.mass, self.inv_mass, self.ks,
                                 self.kd]
        # hinge bending: the term on weights that carry gradients
        self.hinge_count = model.bending.count if model.bending is not None else 0
        if self.hinge_count:
            data = model.bending
            self.hinge_weights = ti.Vector.field(4, real, shape=data.weights.shape[0],
                                                 needs_grad=True)
            self.bending = Bending(SimpleNamespace(bending=SimpleNamespace(
                hinges=data.hinges, weights=self.hinge_weights, start=data.start,
                entries=data.entries, diagonal=data.diagonal)))
            self.parameter_fields.append(self.hinge_weights)
        # wind: the term on numbers that carry gradients
        self.has_wind = model.wind is not None
        if self.has_wind:
            self.wind_params = ti.field(real, shape=model.wind.params.shape[0],
                                        needs_grad=True)
            self.wind = Wind(SimpleNamespace(wind=SimpleNamespace(
                triangles=model.wind.triangles, params=self.wind_params)))
            self.parameter_fields.append(self.wind_params)
        # the membrane: the term on coefficients that carry gradients
        self.triangle_count = model.membrane.count if model.membrane is not None else 0
        if self.triangle_count:
            data = model.membrane
            self.membrane_c = ti.Vector.field(4, real, shape=data.coefficients.shape[0],
                                              needs_grad=True)
            self.membrane = Membrane(SimpleNamespace(particle_count=n, membrane=SimpleNamespace(
                triangles=data.triangles, weights=data.weights, coefficients=self.membrane_c,
                start=data.start, entries=data.entries)))
            self.parameter_fields.append(self.membrane_c)

    def set_contacts(self, rows):
        """The self-contacts of the step whose adjoint comes next: the repelling rows
        (ids (r, 4), kinds (r,)) of the list its forward step read, frozen (the active
        set of the forward run; the kernels' capacity grows where they do not fit)."""
        ids, kinds = rows
        if len(ids) > self.rows.capacity:
            capacity = 1 << int(np.ceil(np.log2(len(ids))))
            self.rows = ContactList(self.model.self_collision, self.inv_mass, capacity)
        self.rows.upload(ids, kinds)

    def plane_vjp(self, x0, planes):
        """The adjoint of the step's start x0 ((n, 3) NumPy) from those of the guard's
        planes there: planes = (ids (k, 4), kinds (k,), n_bar (k, 3), delta_bar (k,)) of
        ``frozen.pull_back``, each a candidate's plane as ``normals.chosen_margin`` makes it
        at x0 (along the normal the forward step chose: a kind carries
        ``normals.SURFACE`` where that was the surfaces')."""
        ids, kinds, n_bar, delta_bar = planes
        k, npr = len(kinds), runtime.numpy_real()
        self.planes.upload(ids, kinds)
        self.n_bar.from_numpy(np.pad(n_bar, ((0, LOG_CAPACITY - k), (0, 0))).astype(npr))
        self.delta_bar.from_numpy(np.pad(delta_bar, (0, LOG_CAPACITY - k)).astype(npr))
        self.x.from_numpy(x0.astype(npr))
        self.x.grad.fill(0)
        self.normals.grad.fill(0)
        self.plane_sum[None] = 0.0
        self.plane_sum.grad[None] = 1.0
        self._planes()
        self._planes.grad()
        return self.x.grad.to_numpy()

    @ti.kernel
    def _planes(self):
        """sum over the planes of n_bar . n + delta_bar delta at x (and the vertex
        normals there)."""
        vertex_normals(self.planes.table, self.x, self.normals)
        for c in range(LOG_CAPACITY):
            if self.planes.repels[c]:
                kind, choice = logged_kind(self.planes.kind[c])
                n, _, delta = chosen_margin(self.planes.ids[c], kind, choice, self.x,
                                            self.planes.table.params[0], self.normals)
                self.plane_sum[None] += self.n_bar[c].dot(n) + self.delta_bar[c] * delta

    def load(self, colliders_off=()):
        """Copy the model's current parameters (after its ``refresh``)."""
        model = self.model
        for mine, theirs in ((self.params, model.params), (self.drag, model.drag),
                             (self.mass, model.mass), (self.inv_mass, model.inv_mass),
                             (self.ks, model.spring_ks), (self.kd, model.spring_kd)):
            mine.copy_from(theirs)
        if self.table is not None:
            self.table.upload(model.scene.colliders, colliders_off)
        if self.hinge_count:
            self.hinge_weights.copy_from(model.bending.weights)
        if self.has_wind:
            self.wind_params.copy_from(model.wind.params)
        if self.triangle_count:
            self.membrane_c.copy_from(model.membrane.coefficients)

    def _gradient_fields(self):
        fields = [field.grad for field in self.parameter_fields]
        if self.table is not None:
            fields += [getattr(self.table.data.grad, key) for key in self.table.data.keys]
        return fields

    def zero_parameter_grads(self):
        for field in self._gradient_fields():
            field.fill(0)

    def parameter_grads(self):
        """The parameters' accumulated gradients (NumPy copies), for ``set_parameter_grads``
        after products that are not to accumulate (an adjoint solve's)."""
        return [field.to_numpy() for field in self._gradient_fields()]

    def set_parameter_grads(self, saved):
        for field, values in zip(self._gradient_fields(), saved):
            field.from_numpy(values)

    def set_inputs(self, x, v, x1=None):
        """The step's start (x, v) and, implicit, its end positions x1 (NumPy (n, 3))."""
        npr = runtime.numpy_real()
        self.x.from_numpy(x.astype(npr))
        self.v.from_numpy(v.astype(npr))
        if self.v_reach is not None:
            self.v_reach.from_numpy(v.astype(npr))
        if x1 is not None:
            self.x1.from_numpy(x1.astype(npr))

    def _kernel(self, friction):
        if friction:
            return self._friction
        if self.projective:
            return self._residual
        return self._gradient

    def evaluate(self, h, t, friction=False):
        """The kernel's output at the inputs set: (n, 3) NumPy. friction (projective):
        the velocities after the friction that follows the solve, instead of the
        residual."""
        self._set_clock(t, h)
        if self.implicit:
            self._kernel(friction)(h, self.rows)
        else:
            self._forces(self.rows)
        return self.out.to_numpy()

    def vjp(self, seed, h, t, friction=False):
        """Reverse mode with the output's adjoint ``seed`` ((n, 3) NumPy): returns the
        inputs' gradients (x, v, x1; x1 None for an explicit step) as NumPy; the
        parameters' gradients accumulate in their fields. friction: as ``evaluate``'s."""
        for field in (self.x, self.v, self.x1, self.v1, self.out):
            field.grad.fill(0)
        self.out.grad.from_numpy(seed.astype(runtime.numpy_real()))
        self._set_clock(t, h)
        if self.implicit:
            kernel = self._kernel(friction)
            kernel(h, self.rows)
            kernel.grad(h, self.rows)
            return self.x.grad.to_numpy(), self.v.grad.to_numpy(), self.x1.grad.to_numpy()
        self._forces(self.rows)
        self._forces.grad(self.rows)
        return self.x.grad.to_numpy(), self.v.grad.to_numpy(), None

    def repeat_vjp(self, seed, h):
        """x1's gradient alone for another seed, after a ``vjp`` or ``evaluate`` of the
        residual at the same inputs, h and time (its values kept in the fields): the
        reverse kernel only, without the forward one and the copies (an adjoint solve's
        products). The parameters' gradients accumulate as in ``vjp``."""
        self.out.grad.from_numpy(seed.astype(runtime.numpy_real()))
        self.v1.grad.fill(0)
        self.x1.grad.fill(0)
        self._kernel(False).grad(h, self.rows)
        return self.x1.grad.to_numpy()

    def _set_clock(self, t, h):
        """t: the time the kernel evaluates at (implicit: the step's end, t - h its start)."""
        self.clock.from_numpy(np.array([t, t - h if self.implicit else t, h],
                                       dtype=runtime.numpy_real()))

    @ti.kernel
    def _forces(self, rows: ti.template()):
        for p in range(self.x.shape[0]):
            t = self.clock[0]
            f = self.gravity.force(p, self.x, self.v, t)
            if ti.static(self.has_colliders):
                f += self.colliders.force(p, self.x, self.v, t)
            self.out[p] = f
        for s in range(self.count):
            i, j = self.pairs[s][0], self.pairs[s][1]
            fi = spring_force(self.x[i], self.x[j], self.v[i], self.v[j], self.ks[s],
                              self.kd[s], self.rest[s])
            self.out[i] += fi
            self.out[j] -= fi
        self._hinges(self.x, -1.0)
        self._wind(0, 1.0)
        if ti.static(self.triangle_count):
            for e in range(self.triangle_count):
                gu, gv = self.membrane.triangle_gradient(e, self.x, self.v)
                self._gather_triangle(e, gu, gv, -1.0)
        if ti.static(self.self_contact):
            for c in range(rows.capacity):
                if rows.repels[c]:      # (the padding's rows have no gap: d = 0)
                    touches, ids, alpha, f = pair_force(rows, c, self.x, self.v)
                    if touches:
                        for j in ti.static(range(4)):
                            self.out[ids[j]] += alpha[j] * f

    @ti.func
    def _gather_triangle(self, e, gu, gv, sign: ti.template()):
        """out += sign (b_iu g_u + b_iv g_v) on triangle e's corners i."""
        ids, b = self.membrane.tris[e], self.membrane.b[e]
        for i in ti.static(range(3)):
            self.out[ids[i]] += sign * (b[i, 0] * gu + b[i, 1] * gv)

    @ti.func
    def _wind(self, when: ti.template(), sign: ti.template()):
        """out += sign times the wind's force at (x, v), at the clock's time ``when`` (0:
        t, 1: the step's start)."""
        if ti.static(self.has_wind):
            for k in range(self.wind.triangles.shape[0]):
                wind = self.wind.velocity(self.clock[when])
                force = self.wind.triangle_force(k, self.x, self.v, wind)
                for q in ti.static(range(3)):
                    self.out[self.wind.triangles[k][q]] += sign * force / 3.0

    @ti.func
    def _hinges(self, x, sign: ti.template()):
        """out += sign c_i s on each hinge's vertex i (s = sum_i c_i x_i): the bending
        energy's gradient (sign 1) or force (-1)."""
        if ti.static(self.hinge_count):
            for k in range(self.hinge_count):
                ids, c = self.bending.hinges[k], self.hinge_weights[k]
                s = self.bending.hinge_vector(k, x)
                for i in ti.static(range(4)):
                    self.out[ids[i]] += sign * c[i] * s

    @ti.func
    def _gap(self, col, x, p, phi, n, x1p, h, fall):
        """The height of x1p above particle p's contact plane with a collider, the plane
        taken from the step's start x[p] (phi, n there) as ``Colliders.begin_solve``
        takes it."""
        free = self.model.inv_mass[p] > 0.0
        return n.dot(x1p) - plane_offset(col, x[p], phi, n, self.v_reach[p], h, fall, free)

    @ti.func
    def _contact_body(self, col, c, x, p, phi, n, ctx):
        """Particle p's contact with collider c in the step's gradient, its lagged normal
        force from the step's start as ``begin_step`` takes it."""
        x1p, h, fall = ctx
        free = self.model.inv_mass[p] > 0.0
        _e, g, _block = step_contact(col, self._gap(col, x, p, phi, n, x1p, h, fall), n, x1p,
                               x[p], h, self.mass[p], lagged_normal_force(col, phi, free), n,
                               False)
        return g

    @ti.func
    def _push_body(self, col, c, x, p, phi, n, ctx):
        """Projective dynamics' penalty and normal damping of particle p at (x1p, v1p)."""
        x1p, v1p, h, fall = ctx
        return plane_contact_force(col, self._gap(col, x, p, phi, n, x1p, h, fall), n, v1p,
                                   self.mass[p], h)

    @ti.func
    def _coulomb_body(self, col, c, x, p, phi, n, ctx):
        """Projective dynamics' friction after the solve (normal velocity change dvn)."""
        x1p, v1p, h, fall, dvn = ctx
        return coulomb_change(col, self._gap(col, x, p, phi, n, x1p, h, fall), n, v1p, dvn)

    @ti.func
    def _end_velocities(self):
        """v1 = (x1 - x) / h (h read from the clock: a kernel's reverse mode takes no
        statement outside its loops, and passing h to a function would be one)."""
        for p in range(self.x.shape[0]):
            self.v1[p] = (self.x1[p] - self.x[p]) / self.clock[2]

    @ti.kernel
    def _residual(self, h: float, rows: ti.template()):
        """Projective dynamics' force residual G(x1; x, v) (its negative: the backward
        Euler gradient's sign), whose zero is the solver's converged step."""
        self._end_velocities()
        for p in range(self.x.shape[0]):
            t = self.clock[0]
            f = self.gravity.force(p, self.x1, self.v1, t)
            if ti.static(self.has_colliders):
                if self.model.inv_mass[p] > 0.0:
                    fall = h * h * self.gravity.gravity().norm()
                    f += self.table.for_each_contact(self.x, p, t - h, self._push_body,
                                                     ti.Vector.zero(float, 3),
                                                     (self.x1[p], self.v1[p], h, fall))
            self.out[p] = self.mass[p] / (h * h) * (self.x1[p] - self.x[p] - h * self.v[p]) - f
        for s in range(self.count):
            i, j = self.pairs[s][0], self.pairs[s][1]
            fi = spring_force(self.x1[i], self.x1[j], self.v1[i], self.v1[j], self.ks[s],
                              self.kd[s], self.rest[s])
            self.out[i] -= fi
            self.out[j] += fi
        self._hinges(self.x1, 1.0)
        self._wind(1, -1.0)      # in Liu's y: the force at the step's start
        if ti.static(self.triangle_count):
            for e in range(self.triangle_count):
                gu, gv = self.membrane.triangle_gradient(e, self.x1, self.v1)
                self._gather_triangle(e, gu, gv, 1.0)

    @ti.kernel
    def _friction(self, h: float, rows: ti.template()):
        """The velocities after projective dynamics' friction (``Projective._friction``):
        v1 = (x1 - x) / h and, at each contact a free particle touches, the approaching
        normal velocity removed and the tangential cut by mu times the normal velocity
        change h |f_n| / m the contact force gave."""
        self._end_velocities()
        for p in range(self.x.shape[0]):
            t = self.clock[1]
            vp = self.v1[p]
            if ti.static(self.has_colliders):
                if self.model.inv_mass[p] > 0.0:
                    fall = h * h * self.gravity.gravity().norm()
                    fn = self.table.for_each_contact(self.x, p, t, self._push_body,
                                                     ti.Vector.zero(float, 3),
                                                     (self.x1[p], vp, h, fall))
                    dvn = 0.0
                    if fn.dot(fn) > 0.0:      # (|f_n|'s derivative exists)
                        dvn = h * fn.norm() * self.inv_mass[p]
                    vp += self.table.for_each_contact(self.x, p, t, self._coulomb_body,
                                                      ti.Vector.zero(float, 3),
                                                      (self.x1[p], vp, h, fall, dvn))
            self.out[p] = vp

    @ti.kernel
    def _gradient(self, h: float, rows: ti.template()):
        for p in range(self.x.shape[0]):
            t = self.clock[0]
            g = self.gravity.incremental(p, self.x1, self.x, h, t)[2]
            if ti.static(self.has_colliders):
                if self.model.inv_mass[p] > 0.0:
                    fall = h * h * self.gravity.gravity().norm()
                    g += self.table.for_each_contact(self.x, p, t - h, self._contact_body,
                                                     ti.Vector.zero(float, 3),
                                                     (self.x1[p], h, fall))
            self.out[p] = g + self.mass[p] / (h * h) * (self.x1[p] - self.x[p] - h * self.v[p])
        for s in range(self.count):
            i, j = self.pairs[s][0], self.pairs[s][1]
            _ei, gi = incremental(self.x1[i], self.x1[j], self.x[i], self.x[j],
                                direction(self.x[i], self.x[j]), self.ks[s], self.kd[s],
                                self.rest[s], h)
            self.out[i] += gi
            self.out[j] -= gi
        self._hinges(self.x1, 1.0)
        self._wind(1, -1.0)      # lagged: the force at the step's start
        if ti.static(self.triangle_count):
            for e in range(self.triangle_count):
                fu, fv = self.membrane.frame(e, self.x1)
                f0u, f0v = self.membrane.frame(e, self.x)
                _em, gu, gv = self.membrane.incremental(fu, fv, f0u, f0v, self.membrane_c[e],
                                                      self.clock[2])
                self._gather_triangle(e, gu, gv, 1.0)
        if ti.static(self.self_contact):
            for c in range(rows.capacity):
                if rows.repels[c]:
                    # the penalty at the end, the damping and friction with the normal
                    # force, normal and weights of the step's start (``SelfContact``)
                    fn0, n0, alpha0 = lagged(rows, c, self.x)
                    ids, alpha, _ep, grad = penalty_gradient(rows, c, self.x1)
                    _ed, g_d, _block_d = dissipation(rows, ids, fn0, n0, alpha0, self.x1, self.x, h,
                                            False)
                    for j in ti.static(range(4)):
                        self.out[ids[j]] += alpha[j] * grad + alpha0[j] * g_d
