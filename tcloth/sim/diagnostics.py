"""Diagnostics: energy, momentum and spring strain, reduced in Taichi kernels over the
scene's terms (each term reports its own potential energy).

Reductions accumulate in float64 where the backend has it (CPU, CUDA).
"""
import numpy as np
import taichi as ti

from .. import runtime
from .. import terms as term_modules
from ..runtime import serial


@ti.kernel
def _particle_sums(x: ti.template(), v: ti.template(), mass: ti.template(),
                   out: ti.template()):
    """out = [kinetic, P (3), L about the origin (3)]."""
    for k in range(7):
        out[k] = 0
    ti.loop_config(serialize=ti.static(serial(x)))
    for p in range(x.shape[0]):
        mv = mass[p] * v[p]
        out[0] += ti.cast(0.5 * mv.dot(v[p]), out.dtype)
        lp = x[p].cross(mv)
        for c in ti.static(range(3)):
            out[1 + c] += ti.cast(mv[c], out.dtype)
            out[4 + c] += ti.cast(lp[c], out.dtype)


class Diagnostics:
    """Reductions over one model; owns its terms and a small accumulator field."""

    def __init__(self, model, contact=None):
        self.model = model
        self.terms = term_modules.build(model, contact=contact)
        self.springs = term_modules.find(self.terms, term_modules.Springs)
        self._out = ti.field(runtime.accumulator(), shape=8)

    def particle_sums(self, state):
        _particle_sums(state.x, state.v, self.model.mass, self._out)
        return self._out.to_numpy().astype(np.float64)

    def energy(self, state):
        """dict of energies in J: kinetic, spring, gravity, contact, (attraction,
        self_contact,) total;
        spring and contact are 0 in a scene without springs or colliders."""
        e = {"kinetic": float(self.particle_sums(state)[0]), "spring": 0.0, "gravity": 0.0,
             "contact": 0.0}
        for term in self.terms:
            value = term.energy(state.x, state.t, self._out)
            if value is not None:
                e[term.name] = float(value)
        e["total"] = sum(e.values())
        return e

    def stored(self, x, t):
        """(P, strain) at positions x and time t: the potential energy of every term but
        gravity (springs, bending, membrane, pressure, contacts, attraction, the grab
        spring; J) and the largest strain of a membrane triangle or of a spring pulling
        harder than ``set_load``'s tension (None without either), for the instability
        test (``instability.py``)."""
        total, strain = 0.0, None
        for term in self.terms:
            if term.name == "gravity":
                continue
            energy, stretch = term.stored(x, t, self._out)
            total += 0.0 if energy is None else float(energy)
            if stretch is not None:
                strain = float(stretch) if strain is None else max(strain, float(stretch))
        return total, strain

    def set_load(self, newtons):
        """The tension below which a spring may pass the strain bound (``stored``)."""
        if self.springs is not None:
            self.springs.load = float(newtons)

    def self_contacts(self, state):
        """Active self-contacts by kind (see ``SelfContact.active``)."""
        term = term_modules.find(self.terms, term_modules.SelfContact)
        return ({"point_triangle": 0, "edge_edge": 0} if term is None
                else term.active(state.x))

    def collider_contacts(self, state):
        """How many free particles are within a collider's thickness now."""
        term = term_modules.find(self.terms, term_modules.Colliders)
        return 0 if term is None else term.touching(state.x, state.t)

    def momentum(self, state):
        """(linear (3,) kg m/s, angular about the origin (3,) kg m^2/s)."""
        sums = self.particle_sums(state)
        return sums[1:4].copy(), sums[4:7].copy()

    def max_strain(self, state):
        """max over springs of (length - rest) / rest; 0 with no springs."""
        return 0.0 if self.springs is None else self.springs.sums(state.x, self._out)[1]
