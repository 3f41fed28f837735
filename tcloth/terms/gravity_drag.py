"""Gravity and viscous air drag: f = m g - c v on every particle (lecture 4).

Potential -m g . x (reported as energy()["gravity"]); drag is dissipative. Backward Euler
takes drag as the dissipation potential c/(2h) |x - x0|^2, whose gradient is c times the
end velocity. Every scene has this term; it is the first, and sets the force accumulator
instead of adding to it.
"""
import taichi as ti

from ..runtime import serial
from .base import Term, particle_energy


@ti.data_oriented
class GravityDrag(Term):
    name = "gravity"
    implicit = "potential"
    projective = "force"
    per_particle = True

    def __init__(self, model):
        self.mass, self.params = model.mass, model.params

    @ti.func
    def gravity(self):
        return ti.Vector([self.params[0], self.params[1], self.params[2]])

    @ti.func
    def force(self, p, x, v, t):
        """m g - c v on particle p; params = (g_x, g_y, g_z, c)."""
        return self.mass[p] * self.gravity() - self.params[3] * v[p]

    @ti.func
    def potential(self, p, x, t):
        return -self.mass[p] * self.gravity().dot(x[p])

    @ti.func
    def accumulate(self, x, v, t, f_out):
        """f_out = m g - c v: sets f_out (the first term of every force evaluation)."""
        ti.loop_config(serialize=ti.static(serial(f_out)))
        for p in range(f_out.shape[0]):
            f_out[p] = self.force(p, x, v, t)

    def energy(self, x, t, out):
        return particle_energy(self, x, t, out)

    @ti.func
    def incremental(self, p, x, x0, h, t):
        """Gravity's -m g . x and drag's c/(2h) |x - x0|^2: (energy, magnitude, gradient)."""
        dx0 = x[p] - x0[p]
        drag = 0.5 * self.params[3] / h * dx0.dot(dx0)
        lin = -self.mass[p] * self.gravity().dot(x[p])
        return drag + lin, drag + ti.abs(lin), (-self.mass[p] * self.gravity()
                                                + self.params[3] / h * dx0)

    @ti.func
    def hessian_block(self, p, x, x0, h, t):
        return self.params[3] / h * ti.Matrix.identity(float, 3)

