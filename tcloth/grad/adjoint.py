"""The vector-Jacobian products of one step: Taichi's reverse mode over the terms' own
``ti.func``s, on copies of the model's parameters that carry gradients.

``StepAdjoint(model, implicit)`` holds those copies (gravity and drag, each spring's
stiffness and damping, the colliders' table) and the step's inputs x, v (and, implicit,
the end positions x1), all with gradients, and one differentiable kernel:

  - explicit (symplectic Euler): the force f(x, v) of gravity and drag, the springs and
    the colliders (``GravityDrag.force``, ``springs.spring_force``, ``Colliders.force``:
    the functions the simulator's kernels call);
  - implicit (backward Euler): the gradient g(x1; x, v) of the step's incremental potential
    (``integrators/potential.py``) over the same terms: inertia M (x1 - x - h v) / h^2,
    gravity and drag (``GravityDrag.incremental``), the springs (``springs.incremental``)
    and the colliders (``colliders.step_contact``), with what the solver fixes at the
    step's start (each spring's damping direction d0, each contact's plane and normal
    force: ``colliders.plane_offset``, ``lagged_normal_force``) computed from x in the same
    kernel, so that their dependence on the step's start is differentiated too.

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
from ..model.collider_table import ColliderTable
from ..features import FEATURES
from ..terms import Bending, Colliders, GravityDrag, Membrane, Wind
from ..terms.colliders import lagged_normal_force, plane_offset, step_contact
from ..terms.springs import direction, incremental, spring_force


COVERED = ("bending", "membrane", "wind")      # the scene features the adjoint takes


def unsupported(scene):
    """Why the adjoint cannot take a step of this scene (one line), or None. It covers
    gravity, drag, springs, hinge bending, the membrane, wind and the analytic colliders
    at rest."""
    features = [f.name for f in FEATURES if getattr(scene, f.name) is not None
                and f.name not in COVERED]
    if scene.wind is not None and scene.wind["callable"] is not None:
        return "a callable gust is not differentiated (give the wind a sinusoidal gust)"
    if features:
        return f"{', '.join(features)} {'is' if len(features) == 1 else 'are'} not " \
               "differentiated yet (the scene sets it)"
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
    particle's drag coefficient), ks, kd (each spring's, in the model's spring order),
    table (the colliders', or None), x, v, x1 (the step's inputs), out (its output: the
    force, or the incremental potential's gradient).
    """

    def __init__(self, model, implicit):
        real, n = runtime.real(), model.particle_count
        self.model, self.implicit = model, implicit
        self.count = model.spring_count
        self.params = ti.field(real, shape=4, needs_grad=True)
        self.drag = ti.field(real, shape=n, needs_grad=True)
        self.ks, self.kd = (ti.field(real, shape=max(self.count, 1), needs_grad=True)
                            for _ in range(2))
        self.x, self.v, self.x1, self.out = (ti.Vector.field(3, real, shape=n, needs_grad=True)
                                             for _ in range(4))
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
        view = SimpleNamespace(mass=model.mass, inv_mass=model.inv_mass, params=self.params,
                               drag=self.drag, colliders=self.table, particle_count=n)
        self.gravity = GravityDrag(view)
        self.colliders = Colliders(view) if self.table is not None else None
        self.has_colliders = self.colliders is not None
        self.mass, self.pairs, self.rest = model.mass, model.spring_pairs, model.spring_rest
        self.parameter_fields = [self.params, self.drag, self.ks, self.kd]
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

    def load(self, colliders_off=()):
        """Copy the model's current parameters (after its ``refresh``)."""
        model = self.model
        for mine, theirs in ((self.params, model.params), (self.drag, model.drag),
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

    def zero_parameter_grads(self):
        for field in self.parameter_fields:
            field.grad.fill(0)
        if self.table is not None:
            for key in self.table.data.keys:
                getattr(self.table.data.grad, key).fill(0)

    def set_inputs(self, x, v, x1=None):
        """The step's start (x, v) and, implicit, its end positions x1 (NumPy (n, 3))."""
        npr = runtime.numpy_real()
        self.x.from_numpy(x.astype(npr))
        self.v.from_numpy(v.astype(npr))
        if self.v_reach is not None:
            self.v_reach.from_numpy(v.astype(npr))
        if x1 is not None:
            self.x1.from_numpy(x1.astype(npr))

    def evaluate(self, h, t):
        """The kernel's output at the inputs set: (n, 3) NumPy."""
        self._set_clock(t, h)
        if self.implicit:
            self._gradient(h)
        else:
            self._forces()
        return self.out.to_numpy()

    def vjp(self, seed, h, t):
        """Reverse mode with the output's adjoint ``seed`` ((n, 3) NumPy): returns the
        inputs' gradients (x, v, x1; x1 None for an explicit step) as NumPy; the
        parameters' gradients accumulate in their fields."""
        for field in (self.x, self.v, self.x1, self.out):
            field.grad.fill(0)
        self.out.grad.from_numpy(seed.astype(runtime.numpy_real()))
        self._set_clock(t, h)
        if self.implicit:
            self._gradient(h)
            self._gradient.grad(h)
            return self.x.grad.to_numpy(), self.v.grad.to_numpy(), self.x1.grad.to_numpy()
        self._forces()
        self._forces.grad()
        return self.x.grad.to_numpy(), self.v.grad.to_numpy(), None

    def _set_clock(self, t, h):
        """t: the time the kernel evaluates at (implicit: the step's end, t - h its start)."""
        self.clock.from_numpy(np.array([t, t - h if self.implicit else t, h],
                                       dtype=runtime.numpy_real()))

    @ti.kernel
    def _forces(self):
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
    def _contact_body(self, col, c, x, p, phi, n, ctx):
        """Particle p's contact with collider c in the step's gradient, its plane and
        lagged normal force taken from the step's start x[p] (phi, n there) as
        ``Colliders.begin_solve`` and ``begin_step`` take them."""
        x1p, h, fall = ctx
        free = self.model.inv_mass[p] > 0.0
        gap = n.dot(x1p) - plane_offset(col, x[p], phi, n, self.v_reach[p], h, fall, free)
        _, g, _ = step_contact(col, gap, n, x1p, x[p], h, self.mass[p],
                               lagged_normal_force(col, phi, free), n)
        return g

    @ti.kernel
    def _gradient(self, h: float):
        for p in range(self.x.shape[0]):
            t = self.clock[0]
            _, _, g = self.gravity.incremental(p, self.x1, self.x, h, t)
            if ti.static(self.has_colliders):
                if self.model.inv_mass[p] > 0.0:
                    fall = h * h * self.gravity.gravity().norm()
                    g += self.table.for_each_contact(self.x, p, t - h, self._contact_body,
                                                     ti.Vector.zero(float, 3),
                                                     (self.x1[p], h, fall))
            self.out[p] = g + self.mass[p] / (h * h) * (self.x1[p] - self.x[p] - h * self.v[p])
        for s in range(self.count):
            i, j = self.pairs[s][0], self.pairs[s][1]
            _, gi = incremental(self.x1[i], self.x1[j], self.x[i], self.x[j],
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
                _, gu, gv = self.membrane.incremental(fu, fv, f0u, f0v, self.membrane_c[e],
                                                      self.clock[2])
                self._gather_triangle(e, gu, gv, 1.0)
