"""Explicit integrators: forward Euler, symplectic Euler, velocity Verlet, RK4.

Each has one entry point ``simulate(model, state_in, state_out, dt)`` and evaluates
forces with its ``Forces`` workspace. RK4 owns one scratch State for its stages; Verlet
caches the forces at the end of its step for the next.
"""
import taichi as ti

from ..runtime import serial
from .base import Integrator


@ti.kernel
def _forward_euler(
        # Model:
        inv_mass: ti.template(),
        # State in:
        x: ti.template(), v: ti.template(), f: ti.template(), dt: float,
        # Out:
        x_out: ti.template(), v_out: ti.template()):
    """x1 = x0 + dt v0;  v1 = v0 + dt M^-1 f(x0, v0)  (lecture 4, both from the old state)."""
    ti.loop_config(serialize=ti.static(serial(x)))
    for p in range(x.shape[0]):
        x_out[p] = x[p] + dt * v[p]
        v_out[p] = v[p] + dt * inv_mass[p] * f[p]


@ti.kernel
def _symplectic_euler(
        # Model:
        inv_mass: ti.template(),
        # State in:
        x: ti.template(), v: ti.template(), f: ti.template(), dt: float,
        # Out:
        x_out: ti.template(), v_out: ti.template()):
    """v1 = v0 + dt M^-1 f(x0, v0);  x1 = x0 + dt v1."""
    ti.loop_config(serialize=ti.static(serial(x)))
    for p in range(x.shape[0]):
        v1 = v[p] + dt * inv_mass[p] * f[p]
        v_out[p] = v1
        x_out[p] = x[p] + dt * v1


@ti.kernel
def _verlet_drift(
        # Model:
        inv_mass: ti.template(),
        # State in:
        x: ti.template(), v: ti.template(), f: ti.template(), dt: float,
        # Out:
        x_out: ti.template(), v_out: ti.template()):
    """Half kick and drift: x1 = x0 + dt (v0 + dt/2 a0). v_out gets v0 + dt a0, an O(dt^2)
    estimate of v1 at which velocity-dependent forces (damping, drag) are evaluated."""
    ti.loop_config(serialize=ti.static(serial(x)))
    for p in range(x.shape[0]):
        a0 = inv_mass[p] * f[p]
        x_out[p] = x[p] + dt * (v[p] + 0.5 * dt * a0)
        v_out[p] = v[p] + dt * a0


@ti.kernel
def _verlet_kick(
        # Model:
        inv_mass: ti.template(),
        # State in:
        f: ti.template(), dt: float, f_out: ti.template(),
        # Out:
        v_out: ti.template()):
    """Second half kick: v1 = v0 + dt/2 (a0 + a1) = (v0 + dt a0) + dt/2 (a1 - a0)."""
    ti.loop_config(serialize=ti.static(serial(v_out)))
    for p in range(v_out.shape[0]):
        v_out[p] += 0.5 * dt * inv_mass[p] * (f_out[p] - f[p])


@ti.kernel
def _rk4_stage(
        # Model:
        inv_mass: ti.template(),
        # State in:
        x0: ti.template(), v0: ti.template(), xs: ti.template(), vs: ti.template(),
        fs: ti.template(), h: float, weight: float, advance: float, first: ti.template(),
        # Out:
        x_out: ti.template(), v_out: ti.template(), xn_out: ti.template(),
        vn_out: ti.template()):
    """One RK4 stage with slope k = (vs, M^-1 fs) at the stage state (xs, vs):
    y_out (+)= weight h k, and the next stage state yn_out = y0 + advance h k."""
    ti.loop_config(serialize=ti.static(serial(x0)))
    for p in range(x0.shape[0]):
        kx = vs[p]
        kv = inv_mass[p] * fs[p]
        if ti.static(first):
            x_out[p] = x0[p] + weight * h * kx
            v_out[p] = v0[p] + weight * h * kv
        else:
            x_out[p] += weight * h * kx
            v_out[p] += weight * h * kv
        xn_out[p] = x0[p] + advance * h * kx
        vn_out[p] = v0[p] + advance * h * kv


class ForwardEuler(Integrator):
    """Forward Euler exactly as in lecture 4. First order; unstable for k_d = 0 at any dt."""
    name = "forward_euler"

    def simulate(self, model, state_in, state_out, dt):
        self.forces_at(state_in)
        _forward_euler(model.inv_mass, state_in.x, state_in.v, state_in.f, dt,
                       state_out.x, state_out.v)
        state_out.t = state_in.t + dt


class SymplecticEuler(Integrator):
    """Semi-implicit (symplectic) Euler: kick then drift. First order, energy bounded."""
    name = "symplectic_euler"

    def simulate(self, model, state_in, state_out, dt):
        self.forces_at(state_in)
        _symplectic_euler(model.inv_mass, state_in.x, state_in.v, state_in.f, dt,
                          state_out.x, state_out.v)
        state_out.t = state_in.t + dt


class Verlet(Integrator):
    """Velocity Verlet, second order. One force evaluation per step: the forces at the end
    of a step are kept in ``state_out.f`` and reused by the next step, unless the state was
    changed in between (``invalidate``)."""
    name = "verlet"

    def __init__(self, model, **options):
        super().__init__(model, **options)
        self._cached = None          # the State whose f holds this integrator's forces

    def forces_at(self, state):
        if self._cached is not state:
            super().forces_at(state)
            self._cached = state

    def invalidate(self):
        self._cached = None

    def holds_forces(self, state):
        return self._cached is state

    def adopt_forces(self, state):
        self._cached = state

    def simulate(self, model, state_in, state_out, dt):
        self.forces_at(state_in)
        _verlet_drift(model.inv_mass, state_in.x, state_in.v, state_in.f, dt,
                      state_out.x, state_out.v)
        state_out.t = state_in.t + dt
        self.forces.compute(state_out.x, state_out.v, state_out.t, state_out.f)
        _verlet_kick(model.inv_mass, state_in.f, dt, state_out.f, state_out.v)
        self._cached = state_out


class RK4(Integrator):
    """Classical fourth-order Runge-Kutta on (x, v); four force evaluations per step."""
    name = "rk4"

    def __init__(self, model, **options):
        super().__init__(model, **options)
        self._stage = model.state()

    def simulate(self, model, state_in, state_out, dt):
        s, x0, v0 = self._stage, state_in.x, state_in.v
        self.forces_at(state_in)
        _rk4_stage(model.inv_mass, x0, v0, x0, v0, state_in.f, dt, 1 / 6, 0.5, True,
                   state_out.x, state_out.v, s.x, s.v)
        t = state_in.t
        for weight, advance, t_stage in ((1 / 3, 0.5, t + dt / 2), (1 / 3, 1.0, t + dt / 2)):
            self.forces.compute(s.x, s.v, t_stage, s.f)
            _rk4_stage(model.inv_mass, x0, v0, s.x, s.v, s.f, dt, weight, advance, False,
                       state_out.x, state_out.v, s.x, s.v)
        self.forces.compute(s.x, s.v, t + dt, s.f)
        _rk4_stage(model.inv_mass, x0, v0, s.x, s.v, s.f, dt, 1 / 6, 0.0, False,
                   state_out.x, state_out.v, s.x, s.v)
        state_out.t = t + dt
