"""Explicit integrators: forward Euler, symplectic Euler, velocity Verlet, RK4.

Each has one entry point ``simulate(model, state_in, state_out, dt)`` and shares
``forces.compute_forces``. None keeps simulation state of its own; RK4 owns one scratch
State for its stages.
"""
import taichi as ti

from ..runtime import serial
from ..forces import compute_forces
from .base import Integrator


@ti.kernel
def _forward_euler(x: ti.template(), v: ti.template(), f: ti.template(), inv_mass: ti.template(),
                   dt: float, x_out: ti.template(), v_out: ti.template()):
    """x1 = x0 + dt v0;  v1 = v0 + dt M^-1 f(x0, v0)  (lecture 4, both from the old state)."""
    ti.loop_config(serialize=ti.static(serial(x)))
    for p in range(x.shape[0]):
        x_out[p] = x[p] + dt * v[p]
        v_out[p] = v[p] + dt * inv_mass[p] * f[p]


@ti.kernel
def _symplectic_euler(x: ti.template(), v: ti.template(), f: ti.template(),
                      inv_mass: ti.template(), dt: float, x_out: ti.template(),
                      v_out: ti.template()):
    """v1 = v0 + dt M^-1 f(x0, v0);  x1 = x0 + dt v1."""
    ti.loop_config(serialize=ti.static(serial(x)))
    for p in range(x.shape[0]):
        v1 = v[p] + dt * inv_mass[p] * f[p]
        v_out[p] = v1
        x_out[p] = x[p] + dt * v1


@ti.kernel
def _verlet_drift(x: ti.template(), v: ti.template(), f: ti.template(), inv_mass: ti.template(),
                  dt: float, x_out: ti.template(), v_out: ti.template()):
    """Half kick and drift: x1 = x0 + dt (v0 + dt/2 a0). v_out gets v0 + dt a0, an O(dt^2)
    estimate of v1 at which velocity-dependent forces (damping, drag) are evaluated."""
    ti.loop_config(serialize=ti.static(serial(x)))
    for p in range(x.shape[0]):
        a0 = inv_mass[p] * f[p]
        x_out[p] = x[p] + dt * (v[p] + 0.5 * dt * a0)
        v_out[p] = v[p] + dt * a0


@ti.kernel
def _verlet_kick(f: ti.template(), inv_mass: ti.template(), dt: float, f_out: ti.template(),
                 v_out: ti.template()):
    """Second half kick: v1 = v0 + dt/2 (a0 + a1) = (v0 + dt a0) + dt/2 (a1 - a0)."""
    ti.loop_config(serialize=ti.static(serial(v_out)))
    for p in range(v_out.shape[0]):
        v_out[p] += 0.5 * dt * inv_mass[p] * (f_out[p] - f[p])


@ti.kernel
def _rk4_stage(x0: ti.template(), v0: ti.template(), xs: ti.template(), vs: ti.template(),
               fs: ti.template(), inv_mass: ti.template(), h: float, weight: float,
               advance: float, first: ti.template(), x_out: ti.template(),
               v_out: ti.template(), xn: ti.template(), vn: ti.template()):
    """One RK4 stage with slope k = (vs, M^-1 fs) at the stage state (xs, vs):
    y_out (+)= weight h k, and the next stage state y_n = y0 + advance h k."""
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
        xn[p] = x0[p] + advance * h * kx
        vn[p] = v0[p] + advance * h * kv


class ForwardEuler(Integrator):
    """Forward Euler exactly as in lecture 4. First order; unstable for k_d = 0 at any dt."""
    name = "forward_euler"

    def simulate(self, model, state_in, state_out, dt):
        self.forces_at(model, state_in)
        _forward_euler(state_in.x, state_in.v, state_in.f, model.inv_mass, dt,
                       state_out.x, state_out.v)
        state_out.t = state_in.t + dt


class SymplecticEuler(Integrator):
    """Semi-implicit (symplectic) Euler: kick then drift. First order, energy bounded."""
    name = "symplectic_euler"

    def simulate(self, model, state_in, state_out, dt):
        self.forces_at(model, state_in)
        _symplectic_euler(state_in.x, state_in.v, state_in.f, model.inv_mass, dt,
                          state_out.x, state_out.v)
        state_out.t = state_in.t + dt


class Verlet(Integrator):
    """Velocity Verlet, second order. One force evaluation per step: the forces at the end
    of a step are kept in ``state_out.f`` and reused by the next step."""
    name = "verlet"

    def simulate(self, model, state_in, state_out, dt):
        self.forces_at(model, state_in)
        _verlet_drift(state_in.x, state_in.v, state_in.f, model.inv_mass, dt,
                      state_out.x, state_out.v)
        state_out.t = state_in.t + dt
        compute_forces(model, state_out.x, state_out.v, state_out.f, state_out.t)
        _verlet_kick(state_in.f, model.inv_mass, dt, state_out.f, state_out.v)
        state_out.forces_valid = True


class RK4(Integrator):
    """Classical fourth-order Runge-Kutta on (x, v); four force evaluations per step."""
    name = "rk4"

    def __init__(self, model, **options):
        super().__init__(model, **options)
        self._stage = model.state()

    def simulate(self, model, state_in, state_out, dt):
        s, x0, v0 = self._stage, state_in.x, state_in.v
        self.forces_at(model, state_in)
        _rk4_stage(x0, v0, x0, v0, state_in.f, model.inv_mass, dt, 1 / 6, 0.5, True,
                   state_out.x, state_out.v, s.x, s.v)
        t = state_in.t
        for weight, advance, t_stage in ((1 / 3, 0.5, t + dt / 2), (1 / 3, 1.0, t + dt / 2)):
            compute_forces(model, s.x, s.v, s.f, t_stage)
            _rk4_stage(x0, v0, s.x, s.v, s.f, model.inv_mass, dt, weight, advance, False,
                       state_out.x, state_out.v, s.x, s.v)
        compute_forces(model, s.x, s.v, s.f, t + dt)
        _rk4_stage(x0, v0, s.x, s.v, s.f, model.inv_mass, dt, 1 / 6, 0.0, False,
                   state_out.x, state_out.v, s.x, s.v)
        state_out.t = t + dt
