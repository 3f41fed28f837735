"""Strain limiting after Provot 1995 ("Deformation constraints in a mass-spring model").

After a step, every limited spring longer than (1 + max_stretch) rest length is shortened
back to that length by moving its ends, weighted by inverse mass (a pinned end stays put).
Corrections of one pass are computed for all springs in parallel and averaged per particle
(Jacobi); ``iterations`` passes. Velocities get the position change divided by dt, so the
state stays consistent with the corrected motion.
"""
import taichi as ti

from . import runtime
from .runtime import serial


@ti.kernel
def _limit_pass(x: ti.template(), inv_mass: ti.template(), pairs: ti.template(),
                rest: ti.template(), index: ti.template(), count: ti.i32, max_stretch: float,
                dx: ti.template(), hits: ti.template()) -> ti.i32:
    """One Jacobi pass; returns how many springs were too long."""
    ti.loop_config(serialize=ti.static(serial(dx)))
    for p in range(dx.shape[0]):
        dx[p] = ti.Vector.zero(float, 3)
        hits[p] = 0
    violated = 0
    ti.loop_config(serialize=ti.static(serial(index)))
    for k in range(count):
        s = index[k]
        i, j = pairs[s][0], pairs[s][1]
        d = x[i] - x[j]
        length = d.norm()
        limit = (1.0 + max_stretch) * rest[s]
        wsum = inv_mass[i] + inv_mass[j]
        if length > limit and wsum > 0.0:
            corr = (length - limit) / (length * wsum) * d
            dx[i] -= inv_mass[i] * corr
            dx[j] += inv_mass[j] * corr
            hits[i] += 1
            hits[j] += 1
            violated += 1
    ti.loop_config(serialize=ti.static(serial(dx)))
    for p in range(dx.shape[0]):
        if hits[p] > 0:
            x[p] += dx[p] / hits[p]
    return violated


@ti.kernel
def _correct_velocities(x_before: ti.template(), x: ti.template(), inv_dt: float,
                        v: ti.template()):
    ti.loop_config(serialize=ti.static(serial(x)))
    for p in range(x.shape[0]):
        v[p] += (x[p] - x_before[p]) * inv_dt


class StrainLimiter:
    """The model's strain limit with its scratch (corrections, hit counts, the positions
    before the passes)."""

    def __init__(self, model):
        self.model = model
        real, n = runtime.real(), model.particle_count
        self.dx = ti.Vector.field(3, real, shape=n)
        self.hits = ti.field(ti.i32, shape=n)
        self.x_before = ti.Vector.field(3, real, shape=n)

    def apply(self, state, dt):
        """Apply the strain limit to ``state`` in place. Returns the number of springs
        still too long before the last pass."""
        m = self.model
        lim = m.strain_limit
        self.x_before.copy_from(state.x)
        violated = 0
        for _ in range(lim["iterations"]):
            violated = _limit_pass(state.x, m.inv_mass, m.spring_pairs, m.spring_rest,
                                   m.limit_index, m.limit_count, lim["max_stretch"],
                                   self.dx, self.hits)
            if violated == 0:
                break
        _correct_velocities(self.x_before, state.x, 1.0 / dt, state.v)
        return violated
