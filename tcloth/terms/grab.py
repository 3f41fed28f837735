"""The grab spring: a zero-rest-length spring from one particle to a target point that
moves at run time (the viewer's mouse drag; ``Simulator.grab``).

On the grabbed particle p, with stiffness k and damping c:

    f = k (target - x_p) - c v_p,    potential k/2 |x_p - target|^2,

and no force anywhere else; c = 2 sqrt(k m_p) (critical for the particle alone) unless
given. Backward Euler takes the spring as a potential and its damping as the dissipation
potential c/(2h) |x_p - x0_p|^2 (as air drag); projective takes the force in every
iteration's residual. A pinned particle cannot be grabbed. The term exists only in a
simulator made with ``grab=True``, so that others compile and launch none of it.
"""
import numpy as np
import taichi as ti

from .. import runtime
from .base import Term, particle_energy


@ti.data_oriented
class GrabSpring:
    """The spring's state as fields: particle (-1: nothing held), target (m) and
    (stiffness N/m, damping N s/m)."""

    def __init__(self):
        self.particle = ti.field(ti.i32, shape=())
        self.target = ti.Vector.field(3, runtime.real(), shape=())
        self.coefficients = ti.field(runtime.real(), shape=2)
        self.release()

    def hold(self, particle, target, stiffness, damping):
        self.target[None] = np.asarray(target, dtype=runtime.numpy_real())
        self.coefficients.from_numpy(np.array([stiffness, damping],
                                              dtype=runtime.numpy_real()))
        self.particle[None] = int(particle)

    def release(self):
        self.particle[None] = -1

    def held(self):
        """None, or dict(particle, target (3,), stiffness, damping)."""
        p = int(self.particle[None])
        if p < 0:
            return None
        k, c = self.coefficients.to_numpy().astype(float)
        return {"particle": p, "target": self.target[None].to_numpy().astype(float),
                "stiffness": float(k), "damping": float(c)}


@ti.data_oriented
class Grab(Term):
    name = "grab"
    implicit = "potential"
    projective = "force"
    per_particle = True

    @staticmethod
    def present(model):
        return model.grab is not None

    def __init__(self, model):
        self.spring = model.grab

    @ti.func
    def accumulate(self, x, v, t, f_out):
        """f_out += the grab spring's force (one particle: no loop)."""
        p = self.spring.particle[None]
        if p >= 0:
            f_out[p] += self.force(p, x, v, t)

    def energy(self, x, t, out):
        return particle_energy(self, x, t, out)

    @ti.func
    def _held(self, p):
        return p == self.spring.particle[None]

    @ti.func
    def force(self, p, x, v, t):
        f = ti.Vector.zero(float, 3)
        if self._held(p):
            f = (self.spring.coefficients[0] * (self.spring.target[None] - x[p])
                 - self.spring.coefficients[1] * v[p])
        return f

    @ti.func
    def potential(self, p, x, t):
        e = 0.0
        if self._held(p):
            d = x[p] - self.spring.target[None]
            e = 0.5 * self.spring.coefficients[0] * d.dot(d)
        return e

    @ti.func
    def incremental(self, p, x, x0, h, t):
        """k/2 |x - target|^2 + c/(2h) |x - x0|^2: (energy, magnitude, gradient)."""
        e = 0.0
        g = ti.Vector.zero(float, 3)
        if self._held(p):
            k, c = self.spring.coefficients[0], self.spring.coefficients[1]
            d = x[p] - self.spring.target[None]
            dx0 = x[p] - x0[p]
            e = 0.5 * k * d.dot(d) + 0.5 * c / h * dx0.dot(dx0)
            g = k * d + c / h * dx0
        return e, e, g

    @ti.func
    def hessian_block(self, p, x, x0, h, t):
        block = ti.Matrix.zero(float, 3, 3)
        if self._held(p):
            block = (self.spring.coefficients[0] + self.spring.coefficients[1] / h) \
                * ti.Matrix.identity(float, 3)
        return block

