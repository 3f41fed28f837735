"""Diagnostics: energy, momentum and spring strain, reduced in Taichi kernels.

Reductions accumulate in float64 where the backend has it (CPU, CUDA).
"""
import numpy as np
import taichi as ti

from . import runtime
from . import colliders
from .runtime import serial


@ti.kernel
def _particle_sums(x: ti.template(), v: ti.template(), mass: ti.template(),
                   params: ti.template(), out: ti.template()):
    """out = [kinetic, gravity potential, P (3), L about the origin (3)]."""
    for k in range(8):
        out[k] = 0
    gravity = ti.Vector([params[0], params[1], params[2]])
    ti.loop_config(serialize=ti.static(serial(x)))
    for p in range(x.shape[0]):
        mv = mass[p] * v[p]
        out[0] += ti.cast(0.5 * mv.dot(v[p]), out.dtype)
        out[1] += ti.cast(-mass[p] * gravity.dot(x[p]), out.dtype)
        lp = x[p].cross(mv)
        for c in ti.static(range(3)):
            out[2 + c] += ti.cast(mv[c], out.dtype)
            out[5 + c] += ti.cast(lp[c], out.dtype)


@ti.kernel
def _spring_sums(x: ti.template(), pairs: ti.template(), ks: ti.template(),
                 rest: ti.template(), count: ti.i32, out: ti.template()):
    """out = [spring potential sum k_s/2 (|x_ij| - l0)^2, max strain (|x_ij| - l0)/l0]."""
    out[0] = 0
    out[1] = -1e30
    ti.loop_config(serialize=ti.static(serial(pairs)))
    for s in range(count):
        i, j = pairs[s][0], pairs[s][1]
        length = (x[i] - x[j]).norm()
        stretch = length - rest[s]
        out[0] += ti.cast(0.5 * ks[s] * stretch * stretch, out.dtype)
        ti.atomic_max(out[1], ti.cast(stretch / rest[s], out.dtype))


@ti.kernel
def _attraction_energy(x: ti.template(), mass: ti.template(), G: float, softening: float,
                       out: ti.template()):
    """out[0] = -sum_{i<j} G m_i m_j / sqrt(r_ij^2 + softening^2)."""
    out[0] = 0
    eps2 = softening * softening
    for i in range(x.shape[0]):
        for j in range(i + 1, x.shape[0]):
            d = x[j] - x[i]
            out[0] += ti.cast(-G * mass[i] * mass[j] / ti.sqrt(d.dot(d) + eps2), out.dtype)


class Diagnostics:
    """Reductions over one model; owns a small accumulator field."""

    def __init__(self, model):
        self.model = model
        self._out = ti.field(runtime.accumulator(), shape=8)

    def particle_sums(self, state):
        _particle_sums(state.x, state.v, self.model.mass, self.model.params, self._out)
        return self._out.to_numpy().astype(np.float64)

    def spring_sums(self, state):
        m = self.model
        if m.spring_count == 0:
            return 0.0, 0.0
        _spring_sums(state.x, m.spring_pairs, m.spring_ks, m.spring_rest, m.spring_count,
                     self._out)
        out = self._out.to_numpy()
        return float(out[0]), float(out[1])

    def energy(self, state):
        """dict of energies in J: kinetic, spring, gravity, contact, (attraction,) total."""
        sums = self.particle_sums(state)
        e = {"kinetic": float(sums[0]), "spring": self.spring_sums(state)[0],
             "gravity": float(sums[1]), "contact": self.contact_energy(state)}
        if self.model.attraction is not None:
            _attraction_energy(state.x, self.model.mass, *self.model.attraction, self._out)
            e["attraction"] = float(self._out.to_numpy()[0])
        e["total"] = sum(e.values())
        return e

    def contact_energy(self, state):
        """Penalty energy of all contacts, J; 0 without colliders."""
        m = self.model
        if not m.collider_count:
            return 0.0
        colliders.contact_energy(state.x, m.inv_mass, m.collider_records, m.collider_ranges, state.t,
                       self._out)
        return float(self._out.to_numpy()[0])

    def momentum(self, state):
        """(linear (3,) kg m/s, angular about the origin (3,) kg m^2/s)."""
        sums = self.particle_sums(state)
        return sums[2:5].copy(), sums[5:8].copy()

    def max_strain(self, state):
        """max over springs of (length - rest) / rest; 0 with no springs."""
        return self.spring_sums(state)[1]
