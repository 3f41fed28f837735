"""Wind: quadratic forces on cloth triangles after Wejchert & Haumann 1991.

On a triangle of area A and unit normal n, with v_rel = wind(t) - (the mean velocity of
its particles), u = v_rel . n and v_t = v_rel - u n:

    f = A (drag u |u| n + tangential |v_t| v_t + lift |u| v_t),

split equally onto its three particles (``Scene.set_wind``). The wind velocity is the
mean plus a sinusoidal gust evaluated in the kernel (its numbers in the model's
``wind.params``), or a Python callable of t evaluated once per force evaluation and
uploaded (``features.wind``). No potential; backward Euler and projective take it at the
start of the step.
"""
import taichi as ti

from ..features.wind import WIND, pack, wind_velocity
from ..runtime import serial
from .base import Term, norm_above


@ti.data_oriented
class Wind(Term):
    """The scene's wind on its cloth triangles (absent without cloth)."""
    feature = WIND

    @staticmethod
    def present(model):
        return model.wind is not None

    def __init__(self, model):
        self.model = model
        self.triangles, self.params = model.wind.triangles, model.wind.params

    def prepare(self, t):
        """A callable gust: its velocity at t into ``params``."""
        wind = self.model.wind.settings
        if wind["callable"] is not None:
            self.params.from_numpy(pack(wind, wind_velocity(wind, t)))

    def batch_obstacle(self):
        if self.model.wind.settings["callable"] is not None:
            return "the wind's gust is a Python callable, evaluated between substeps"
        if not serial(self.triangles):
            return f"the wind's {self.triangles.shape[0]} triangles run on several threads"
        return None

    @ti.func
    def velocity(self, t):
        """The wind's velocity at time t: the mean plus the sinusoidal gust. params =
        (velocity (3), gust amplitude (3), frequency, phase, drag, lift, tangential)."""
        params = ti.static(self.params)
        return ti.Vector([params[0], params[1], params[2]]) + ti.Vector(
            [params[3], params[4], params[5]]) * ti.sin(2.0 * 3.141592653589793 * params[6] * t
                                                        + params[7])

    @ti.func
    def triangle_force(self, k, x, v, wind):
        """The Wejchert & Haumann force on triangle k in the wind velocity ``wind`` (all of
        it: a third goes to each particle)."""
        params, triangles = ti.static(self.params, self.triangles)
        a, b, c = triangles[k][0], triangles[k][1], triangles[k][2]
        cross = (x[b] - x[a]).cross(x[c] - x[a])
        twice_area = cross.norm()
        force = ti.Vector.zero(float, 3)
        if twice_area > 0.0:
            n = cross / twice_area
            area = 0.5 * twice_area
            v_rel = wind - (v[a] + v[b] + v[c]) / 3.0
            u = v_rel.dot(n)
            vt = v_rel - u * n
            # (|vt| vt's derivative is 0 where a wind along the normal leaves vt = 0)
            force = area * (params[8] * u * abs(u) * n
                            + params[10] * norm_above(vt, 0.0) * vt
                            + params[9] * abs(u) * vt)
        return force

    @ti.func
    def accumulate(self, x, v, t, f_out):
        """Wejchert & Haumann quadratic wind on every triangle, a third to each particle."""
        wind = self.velocity(t)
        ti.loop_config(serialize=ti.static(serial(self.triangles)))
        for k in range(self.triangles.shape[0]):
            force = self.triangle_force(k, x, v, wind)
            for q in ti.static(range(3)):
                f_out[self.triangles[k][q]] += force / 3.0
