"""Explicit integrators: forward Euler, symplectic Euler, velocity Verlet, RK4.

Each step exists twice over the same ``ti.func``s: ``simulate(model, state_in, state_out,
dt)`` runs one step from Python (a launch for the forces, one per update), and
``advance(a, b, t, dt, fresh)`` is the whole step as a ``ti.func`` that leaves its result in
State a (b is scratch), which the simulator's batches run n times in one launch
(``batch.py``). The update functions take the state to read and the state to write, which
may be the same: each particle's new values depend only on its own old ones. Forces are
evaluated with the ``Forces`` workspace. RK4 owns one scratch State for its stages and
reads its coefficients from a field (both paths then do the same arithmetic); Verlet
caches the forces at the end of its step for the next.

In ``advance``, t and dt are float64 (the time of state a is computed in the kernel as the
simulator computes it in Python) and cast to the working precision where a step from
Python would pass them; fresh: whether a's forces must be evaluated (Verlet; the others
always evaluate them).
"""
import numpy as np
import taichi as ti

from .. import runtime
from ..runtime import serial
from .base import ForceCache, Integrator
from .linalg import copy


@ti.kernel
def _phase(integrator: ti.template(), phase: ti.template(), a: ti.template(),
           b: ti.template(), dt: float):
    """One update phase (a ``ti.func`` of the integrator named by ``phase``) from Python."""
    ti.static(getattr(integrator, phase))(a, b, dt)


@ti.data_oriented
class _OneEvaluation(Integrator):
    """A step that evaluates the forces at its start and then updates every particle
    (``update(a, b, dt)``)."""
    batched = True

    def simulate(self, model, state_in, state_out, dt):
        self.forces_at(state_in)
        _phase(self, "update", state_in, state_out, dt)
        state_out.t = state_in.t + dt

    @ti.func
    def advance(self, a, b, t, dt, fresh):
        self.forces.accumulate(a.x, a.v, ti.cast(t, float), a.f)
        self.update(a, a, ti.cast(dt, float))


@ti.data_oriented
class ForwardEuler(_OneEvaluation):
    """Forward Euler: x' = x + dt v, v' = v + dt f(x, v) / m, both from the state at the
    start of the step. First order; unstable for k_d = 0 at any dt."""
    name = "forward_euler"

    @ti.func
    def update(self, a, b, dt):
        """x1 = x0 + dt v0;  v1 = v0 + dt M^-1 f(x0, v0)  (both from the old state)."""
        ti.loop_config(serialize=ti.static(serial(a.x)))
        for p in range(a.x.shape[0]):
            b.x[p] = a.x[p] + dt * a.v[p]
            b.v[p] = a.v[p] + dt * self.inv_mass[p] * a.f[p]


@ti.data_oriented
class SymplecticEuler(_OneEvaluation):
    """Semi-implicit (symplectic) Euler: kick then drift. First order, energy bounded."""
    name = "symplectic_euler"

    @ti.func
    def update(self, a, b, dt):
        """v1 = v0 + dt M^-1 f(x0, v0);  x1 = x0 + dt v1."""
        ti.loop_config(serialize=ti.static(serial(a.x)))
        for p in range(a.x.shape[0]):
            v1 = a.v[p] + dt * self.inv_mass[p] * a.f[p]
            b.v[p] = v1
            b.x[p] = a.x[p] + dt * v1


@ti.kernel
def _kick(integrator: ti.template(), v: ti.template(), f_end: ti.template(),
          f_start: ti.template(), dt: float):
    integrator.kick(v, f_end, f_start, dt, False)


@ti.data_oriented
class Verlet(ForceCache, Integrator):
    """Velocity Verlet, second order. One force evaluation per step: the forces at the end
    of a step are kept in ``state_out.f`` and reused by the next step, unless the state was
    changed in between (``invalidate``)."""
    name = "verlet"
    batched = True

    def forces_at(self, state):
        if self._cached is not state:
            super().forces_at(state)
            self._cached = state

    @ti.func
    def drift(self, a, b, dt):
        """Half kick and drift: x1 = x0 + dt (v0 + dt/2 a0). b.v gets v0 + dt a0, an O(dt^2)
        estimate of v1 at which velocity-dependent forces (damping, drag) are evaluated."""
        ti.loop_config(serialize=ti.static(serial(a.x)))
        for p in range(a.x.shape[0]):
            a0 = self.inv_mass[p] * a.f[p]
            b.x[p] = a.x[p] + dt * (a.v[p] + 0.5 * dt * a0)
            b.v[p] = a.v[p] + dt * a0

    @ti.func
    def kick(self, v, f_end, f_start, dt, keep: ti.template()):
        """Second half kick: v1 = v0 + dt/2 (a0 + a1) = (v0 + dt a0) + dt/2 (a1 - a0);
        keep: f_start = f_end after (the step's result is in f_start's State)."""
        ti.loop_config(serialize=ti.static(serial(v)))
        for p in range(v.shape[0]):
            v[p] += 0.5 * dt * self.inv_mass[p] * (f_end[p] - f_start[p])
            if ti.static(keep):
                f_start[p] = f_end[p]

    def simulate(self, model, state_in, state_out, dt):
        self.forces_at(state_in)
        _phase(self, "drift", state_in, state_out, dt)
        state_out.t = state_in.t + dt
        self.forces.compute(state_out.x, state_out.v, state_out.t, state_out.f)
        _kick(self, state_out.v, state_out.f, state_in.f, dt)
        self._cached = state_out

    @ti.func
    def advance(self, a, b, t, dt, fresh):
        # one force evaluation in the code, run at the start (when fresh) and at the end:
        # each copy of the terms' code inlined adds to the batch's compile time
        h = ti.cast(dt, float)
        for end in range(2):
            if end or fresh:
                t_forces = t
                if end:
                    t_forces = t + dt
                self.forces.accumulate(a.x, a.v, ti.cast(t_forces, float), b.f)
                if not end:
                    copy(a.f, b.f)
            if not end:
                self.drift(a, a, h)
        self.kick(a.v, b.f, a.f, h, True)


# RK4's four stages: y1 = y0 + sum_k weight_k h k_k; the next stage's state y0 + advance_k h k_k
_RK4_WEIGHTS, _RK4_ADVANCES = (1 / 6, 1 / 3, 1 / 3, 1 / 6), (0.5, 0.5, 1.0, 0.0)


@ti.kernel
def _rk4_stage(integrator: ti.template(), a: ti.template(), xs: ti.template(),
               vs: ti.template(), fs: ti.template(), h: float, k: ti.i32,
               acc_in: ti.template(), acc_out: ti.template()):
    integrator.stage(a, xs, vs, fs, h, k, acc_in, acc_out)


@ti.data_oriented
class RK4(Integrator):
    """Classical fourth-order Runge-Kutta on (x, v); four force evaluations per step."""
    name = "rk4"
    batched = True

    def __init__(self, model, contact=None, **options):
        super().__init__(model, contact, **options)
        self._stage = model.state()
        self._coefficients = ti.field(runtime.real(), shape=8)
        self._coefficients.from_numpy(np.array(_RK4_WEIGHTS + _RK4_ADVANCES,
                                               dtype=runtime.numpy_real()))

    @ti.func
    def stage(self, a, xs, vs, fs, h, k, acc_in, acc_out):
        """Stage k with slope (vs, M^-1 fs) at the stage state (xs, vs): acc_out.y =
        acc_in.y + weight_k h slope (acc_in is a on the first stage), and the next stage
        state a.y + advance_k h slope into the scratch State. acc_out may be a."""
        weight, advance = self._coefficients[k], self._coefficients[4 + k]
        ti.loop_config(serialize=ti.static(serial(a.x)))
        for p in range(a.x.shape[0]):
            kx = vs[p]
            kv = self.inv_mass[p] * fs[p]
            sx = a.x[p] + advance * h * kx
            sv = a.v[p] + advance * h * kv
            acc_out.x[p] = acc_in.x[p] + weight * h * kx
            acc_out.v[p] = acc_in.v[p] + weight * h * kv
            self._stage.x[p] = sx
            self._stage.v[p] = sv

    def simulate(self, model, state_in, state_out, dt):
        s, t = self._stage, state_in.t
        self.forces_at(state_in)
        _rk4_stage(self, state_in, state_in.x, state_in.v, state_in.f, dt, 0, state_in,
                   state_out)
        for k in range(1, 4):
            self.forces.compute(s.x, s.v, t + dt if k == 3 else t + dt / 2, s.f)
            _rk4_stage(self, state_in, s.x, s.v, s.f, dt, k, state_out, state_out)
        state_out.t = t + dt

    @ti.func
    def advance(self, a, b, t, dt, fresh):
        # the stages in a loop: one copy of the terms' code (see Verlet.advance); the
        # first stage's state and the sum start as copies of a
        s = self._stage
        h = ti.cast(dt, float)
        copy(s.x, a.x)
        copy(s.v, a.v)
        copy(b.x, a.x)
        copy(b.v, a.v)
        for k in range(4):
            t_stage = t
            if k == 3:
                t_stage = t + dt
            elif k > 0:
                t_stage = t + dt / 2
            self.forces.accumulate(s.x, s.v, ti.cast(t_stage, float), s.f)
            self.stage(a, s.x, s.v, s.f, h, k, b, b)
        copy(a.x, b.x)
        copy(a.v, b.v)
