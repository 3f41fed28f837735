"""Gravity and viscous air drag: f = m g - c_p v on every particle.

The drag coefficient of particle p is c_p = c + gamma m_p (``Model.drag``): the scene's
``air_drag`` c, the same on every particle, plus its ``air_damping`` gamma times the
particle's mass (Rayleigh mass damping, which means the same at every resolution: a cloth
falls at the terminal speed g / gamma however finely it is sampled).
Potential -m g . x (reported as energy()["gravity"]); drag is dissipative. Backward Euler
takes drag as the dissipation potential c_p/(2h) |x - x0|^2, whose gradient is c_p times
the end velocity. Every scene has this term; it is the first, and sets the force
accumulator instead of adding to it.
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
        self.mass, self.params, self.drag = model.mass, model.params, model.drag

    @ti.func
    def gravity(self):
        return ti.Vector([self.params[0], self.params[1], self.params[2]])

    @ti.func
    def force(self, p, x, v, t):
        """m g - c_p v on particle p; params[:3] = g, drag[p] = c_p."""
        return self.mass[p] * self.gravity() - self.drag[p] * v[p]

    @ti.func
    def potential(self, p, x, t):
        return -self.mass[p] * self.gravity().dot(x[p])

    @ti.func
    def accumulate(self, x, v, t, f_out):
        """f_out = m g - c_p v: sets f_out (the first term of every force evaluation)."""
        ti.loop_config(serialize=ti.static(serial(f_out)))
        for p in range(f_out.shape[0]):
            f_out[p] = self.force(p, x, v, t)

    def energy(self, x, t, out):
        return particle_energy(self, x, t, out)

    @ti.func
    def incremental(self, p, x, x0, h, t):
        """Gravity's -m g . x and drag's c_p/(2h) |x - x0|^2: (energy, magnitude, gradient)."""
        dx0 = x[p] - x0[p]
        drag = 0.5 * self.drag[p] / h * dx0.dot(dx0)
        lin = -self.mass[p] * self.gravity().dot(x[p])
        return drag + lin, drag + ti.abs(lin), (-self.mass[p] * self.gravity()
                                                + self.drag[p] / h * dx0)

    @ti.func
    def hessian_block(self, p, x, x0, h, t):
        return self.drag[p] / h * ti.Matrix.identity(float, 3)

