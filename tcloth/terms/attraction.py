"""Inverse-square attraction between all particle pairs (O(n^2)), Plummer-softened:

    f_i = sum_j G m_i m_j (x_j - x_i) / (|x_j - x_i|^2 + eps^2)^(3/2),

potential -G m_i m_j / sqrt(r^2 + eps^2) per pair (energy()["attraction"]). Backward Euler
and projective take it at the start of the step.
"""
import taichi as ti

from ..features.attraction import ATTRACTION
from ..runtime import serial_count
from .base import Term


@ti.kernel
def attraction_energy(x: ti.template(), mass: ti.template(), G: float, softening: float,
                      out: ti.template()):
    """out[0] = -sum_{i<j} G m_i m_j / sqrt(r_ij^2 + softening^2)."""
    out[0] = 0
    eps2 = softening * softening
    for i in range(x.shape[0]):
        for j in range(i + 1, x.shape[0]):
            d = x[j] - x[i]
            out[0] += ti.cast(-G * mass[i] * mass[j] / ti.sqrt(d.dot(d) + eps2), out.dtype)


@ti.data_oriented
class Attraction(Term):
    name = "attraction"
    feature = ATTRACTION

    @staticmethod
    def present(model):
        return model.attraction is not None

    def __init__(self, model):
        self.mass = model.mass
        self.G, self.softening = model.attraction.G, model.attraction.softening

    def batch_obstacle(self):
        n = self.mass.shape[0]
        if not serial_count(n * n):
            return f"the attraction's {n} x {n} pairs run on several threads"
        return None

    @ti.func
    def accumulate(self, x, v, t, f_out):
        """Softened inverse-square attraction, gathered per particle over all others (on
        one thread below ``serial_below`` pairs)."""
        eps2 = self.softening * self.softening
        mass = ti.static(self.mass)
        ti.loop_config(serialize=ti.static(serial_count(x.shape[0] * x.shape[0])))
        for i in range(x.shape[0]):
            acc = ti.Vector.zero(float, 3)
            for j in range(x.shape[0]):
                if j != i:
                    d = x[j] - x[i]
                    r2 = d.dot(d) + eps2
                    acc += mass[j] * d / (r2 * ti.sqrt(r2))
            f_out[i] += self.G * mass[i] * acc

    def energy(self, x, t, out):
        attraction_energy(x, self.mass, self.G, self.softening, out)
        return float(out.to_numpy()[0])
