"""Backward Euler's incremental potential over the scene's terms.

One step of size h from (x0, v0) minimises

    E(x) = 1/(2 h^2) |x - x0 - h v0|_M^2 + sum over the "potential" terms - f_lag . x

whose gradient vanishes exactly at the backward Euler step. Each potential term
(``terms/``) gives its energy, gradient and Hessian blocks; the "lagged" terms (wind,
attraction) enter as the constant force f_lag evaluated at the start of the step.
Pinned particles' entries are left out of E (they move with x0 + h v0).
"""
import numpy as np
import taichi as ti

from .. import runtime
from .. import terms as term_modules
from ..terms.forces import Forces
from ..runtime import serial


@ti.data_oriented
class IncrementalPotential:
    """E, its gradient and the terms' Hessian blocks for one model.

    Attributes:
        x0, x_hat: the step's start and inertial prediction x0 + h v0, (n,) vec3.
        grad: the gradient of the last evaluation with ``with_grad``, (n,) vec3.
        particle_terms: the per-particle potential terms (gravity and drag, colliders,
            the mesh colliders' hold).
        springs: the Springs term or None.
        pair_terms: the other potential terms (bending, membrane, pressure, self-contact),
            which provide "couplings" (``terms/base.py``).

    ``contact`` is the simulator's contact stage or None; ``term_options`` go to the terms
    that declare them (``terms.build``).
    """

    def __init__(self, model, contact=None, **term_options):
        n, real = model.particle_count, runtime.real()
        terms = term_modules.build(model, lambda cls: cls.implicit == "potential",
                                   contact, **term_options)
        self.particle_terms = tuple(t for t in terms if t.per_particle)
        # the mesh colliders' planes as a penalty, on while a solver holds the cloth to
        # them (``contact/hold.py``; weight 0 otherwise)
        self.hold = contact.hold if contact is not None else None
        if self.hold is not None:
            self.particle_terms += (self.hold,)
        self.springs = term_modules.find(terms, term_modules.Springs)
        self.pair_terms = tuple(t for t in terms if not t.per_particle and t is not self.springs)
        self.terms = terms
        self.lagged = Forces(model, lambda cls: cls.implicit == "lagged", contact)
        self.has_lagged = bool(self.lagged.terms)
        self.mass, self.inv_mass = model.mass, model.inv_mass
        self.x_hat, self.x0, self.grad, self.f_lag = (
            ti.Vector.field(3, real, shape=n) for _ in range(4))
        self.acc = ti.field(runtime.accumulator(), shape=2)     # E, sum of |terms|
        self._eps = float(np.finfo(runtime.numpy_real()).eps)

    def begin(self, x, v, h, t0, x_start):
        """Start a step from positions x, velocities v at time t0: x0, x_hat, the lagged
        quantities of every term, f_lag; the Newton iterate x_start = x_hat. The terms
        read the step's start from the copy x0: x_start may be x itself (VBD's substeps
        after the first start from the State they write), which then holds x_hat."""
        self._begin_particles(x, v, h, x_start)
        for term in self.terms:
            term.begin_step(self.x0, t0)
            term.begin_solve(self.x0, v, h, t0)
        if self.has_lagged:
            self.lagged.compute(self.x0, v, t0, self.f_lag)

    def evaluate(self, x, h, t, with_grad):
        """(E at x, a bound on the rounding error of comparing two such evaluations:
        8 ulps of the sum of the terms' magnitudes); the gradient into ``grad`` when
        ``with_grad``."""
        self._particle_terms(x, h, t, with_grad)
        if self.springs is not None:
            self.springs.add_incremental(x, self.x0, h, with_grad, self.acc, self.grad)
        for term in self.pair_terms:
            term.add_incremental(x, self.x0, h, with_grad, self.acc, self.grad)
        energy, magnitude = self._sums()
        return energy, 8.0 * self._eps * magnitude

    def prepare_blocks(self, x, h):
        """The pair terms' diagonal blocks at x, before a kernel reads ``particle_block``."""
        for term in self.pair_terms:
            term.prepare_blocks(x, self.x0, h)

    @ti.func
    def particle_block(self, p, x, h, t):
        """Particle p's diagonal Hessian block without springs: ``inertial_block`` and the
        pair terms' diagonal blocks."""
        block = self.inertial_block(p, x, h, t)
        for term in ti.static(self.pair_terms):
            block += term.diagonal_block(p)
        return block

    @ti.func
    def inertial_block(self, p, x, h, t):
        """Inertia M/h^2 and the per-particle terms' blocks of particle p."""
        block = self.mass[p] / (h * h) * ti.Matrix.identity(float, 3)
        for term in ti.static(self.particle_terms):
            block += term.hessian_block(p, x, self.x0, h, t)
        return block

    @ti.kernel
    def _sums(self) -> ti.types.vector(2, ti.f64):
        return ti.Vector([self.acc[0], self.acc[1]], ti.f64)

    @ti.kernel
    def _begin_particles(self, x: ti.template(), v: ti.template(), h: float,
                         x_start: ti.template()):
        self.begin_particles(x, v, h, x_start)

    @ti.func
    def begin_particles(self, x, v, h, x_start):
        """x0 = x, x_hat = x + h v, x_start = x_hat."""
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            self.x0[p] = x[p]
            self.x_hat[p] = x[p] + h * v[p]
            x_start[p] = self.x_hat[p]

    @ti.kernel
    def _particle_terms(self, x: ti.template(), h: float, t: float, with_grad: ti.template()):
        """Inertia, the per-particle terms and the lagged forces; the first of E's kernels
        (sets acc to 0 and, with_grad, grad)."""
        self.acc[0] = 0.0
        self.acc[1] = 0.0
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            dxh = x[p] - self.x_hat[p]
            e = 0.5 * self.mass[p] / (h * h) * dxh.dot(dxh)
            magnitude = e
            g = self.mass[p] / (h * h) * dxh
            for term in ti.static(self.particle_terms):
                e_t, m_t, g_t = term.incremental(p, x, self.x0, h, t)
                e += e_t
                magnitude += m_t
                g += g_t
            if ti.static(self.has_lagged):
                work = self.f_lag[p].dot(x[p])
                e -= work
                magnitude += ti.abs(work)
                g -= self.f_lag[p]
            if self.inv_mass[p] > 0.0:
                self.acc[0] += ti.cast(e, self.acc.dtype)
                self.acc[1] += ti.cast(magnitude, self.acc.dtype)
            if ti.static(with_grad):
                self.grad[p] = g
