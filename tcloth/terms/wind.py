"""Wind: quadratic forces on cloth triangles after Wejchert & Haumann 1991.

On a triangle of area A and unit normal n, with v_rel = wind(t) - (the mean velocity of
its particles), u = v_rel . n and v_t = v_rel - u n:

    f = A (drag u |u| n + tangential |v_t| v_t + lift |u| v_t),

split equally onto its three particles (``Scene.set_wind``). The wind velocity is the
mean plus a sinusoidal gust evaluated in the kernel (its numbers in the model's
``wind_params``), or a Python callable of t evaluated once per force evaluation and
uploaded. No potential; backward Euler and projective take
it at the start of the step.
"""
import numpy as np
import taichi as ti

from .. import runtime
from ..errors import SceneError
from ..runtime import serial
from ..validate import as_scalar, as_vec3
from .base import Feature, Term


def wind_velocity(wind, t):
    """The wind velocity (3,) at time t of a ``Scene.wind`` dict (validated)."""
    f = wind["callable"]
    if f is None:
        return wind["velocity"] + wind["amplitude"] * np.sin(
            2 * np.pi * wind["frequency"] * t + wind["phase"])
    try:
        value = f(t)
    except Exception as e:
        raise SceneError(f"wind gust callable raised {type(e).__name__} at t = {t}: {e}") from e
    try:
        return as_vec3("wind gust callable's result", value)
    except SceneError as e:
        raise SceneError(f"{e} at t = {t}") from None


def pack(wind, velocity):
    """The ``Model.wind_params`` values of a ``Scene.wind`` dict with this mean velocity."""
    return np.array([*velocity, *wind["amplitude"], wind["frequency"], wind["phase"],
                     wind["drag"], wind["lift"], wind["tangential"]],
                    dtype=runtime.numpy_real())


class WindFeature(Feature):
    """``Scene.set_wind``; the model's triangles and ``wind_params``; live (the mean
    velocity). A callable gust cannot be checkpointed."""
    name, method, live = "wind", "set_wind", True

    def set(self, scene, velocity=(0.0, 0.0, 0.0), drag=0.5, lift=0.0, tangential=0.0,
            gust=None):
        """Quadratic wind on cloth triangles (Wejchert & Haumann 1991).

        On a triangle of area A and unit normal n, with relative velocity
        v_rel = wind(t) - (mean velocity of its particles), u = v_rel . n and its in-plane
        part v_t = v_rel - u n, the force is
            drag * A * u |u| n                 (pressure drag, normal)
          + tangential * A * |v_t| v_t         (skin friction, tangential)
          + lift * A * |u| v_t                 (lift: tangential, largest at 45 degrees,
                                                zero face-on and edge-on),
        split equally onto its three particles. drag carries the air density and the 1/2
        (kg/m^3): for air, 0.5 * 1.2 * C_d with C_d about 1 gives 0.6.

        Args:
            velocity: (3,) mean wind, m/s.
            drag, lift, tangential: coefficients >= 0, kg/m^3.
            gust: None; a dict(amplitude=(3,), frequency=Hz, phase=rad) adding
                amplitude * sin(2 pi frequency t + phase) in the kernel; or a callable
                t -> (3,) wind velocity evaluated once per force evaluation (velocity is
                then ignored). Neither recompiles kernels.
        """
        wind = {"velocity": as_vec3("velocity", velocity),
                "drag": as_scalar("drag", drag, minimum=0.0),
                "lift": as_scalar("lift", lift, minimum=0.0),
                "tangential": as_scalar("tangential", tangential, minimum=0.0),
                "amplitude": np.zeros(3), "frequency": 0.0, "phase": 0.0, "callable": None}
        if callable(gust):
            wind["callable"] = gust
            wind_velocity(wind, 0.0)
        elif isinstance(gust, dict):
            unknown = sorted(set(gust) - {"amplitude", "frequency", "phase"})
            if unknown:
                raise SceneError(f"gust has an unknown key {unknown[0]!r} "
                                 "(keys: amplitude, frequency, phase)")
            wind["amplitude"] = as_vec3("gust['amplitude']", gust.get("amplitude", (0, 0, 0)))
            wind["frequency"] = as_scalar("gust['frequency']", gust.get("frequency", 0.0), 0.0)
            wind["phase"] = as_scalar("gust['phase']", gust.get("phase", 0.0))
        elif gust is not None:
            raise SceneError(f"gust must be None, a dict or a callable t -> (3,) (got {gust!r})")
        return wind

    def saved(self, wind):
        if wind.get("callable") is not None:
            raise SceneError("a scene whose wind gust is a Python callable cannot be saved in "
                             "a checkpoint; use gust=dict(amplitude=..., frequency=..., phase=...)")
        return {"velocity": wind["velocity"], "drag": wind["drag"], "lift": wind["lift"],
                "tangential": wind["tangential"],
                "gust": {k: wind[k] for k in ("amplitude", "frequency", "phase")}}

    def build(self, model, wind):
        """The cloth triangles and the wind's parameter field (None without cloth)."""
        triangles = model.scene.triangles
        if not len(triangles):
            return None
        model.triangle_count = len(triangles)
        model.triangles = ti.Vector.field(3, ti.i32, shape=len(triangles))
        model.triangles.from_numpy(triangles.astype(np.int32))
        model.wind_params = ti.field(runtime.real(), shape=11)
        return wind

    def refresh(self, model, wind):
        model.wind_params.from_numpy(pack(wind, wind["velocity"]))
        return wind


WIND = WindFeature()


@ti.data_oriented
class Wind(Term):
    """The scene's wind on its cloth triangles (absent without cloth)."""
    feature = WIND

    @staticmethod
    def present(model):
        return model.wind is not None

    def __init__(self, model):
        self.model = model
        self.triangles, self.params = model.triangles, model.wind_params

    def prepare(self, t):
        """A callable gust: its velocity at t into ``params``."""
        wind = self.model.wind
        if wind["callable"] is not None:
            self.params.from_numpy(pack(wind, wind_velocity(wind, t)))

    def batch_obstacle(self):
        if self.model.wind["callable"] is not None:
            return "the wind's gust is a Python callable, evaluated between substeps"
        if not serial(self.triangles):
            return f"the wind's {self.triangles.shape[0]} triangles run on several threads"
        return None

    @ti.func
    def accumulate(self, x, v, t, f_out):
        """Wejchert & Haumann quadratic wind on every triangle, a third to each particle.

        params = (velocity (3), gust amplitude (3), frequency, phase, drag, lift,
        tangential)."""
        params, triangles = ti.static(self.params, self.triangles)
        wind = ti.Vector([params[0], params[1], params[2]]) + ti.Vector(
            [params[3], params[4], params[5]]) * ti.sin(2.0 * 3.141592653589793 * params[6] * t
                                                        + params[7])
        ti.loop_config(serialize=ti.static(serial(triangles)))
        for k in range(triangles.shape[0]):
            a, b, c = triangles[k][0], triangles[k][1], triangles[k][2]
            cross = (x[b] - x[a]).cross(x[c] - x[a])
            twice_area = cross.norm()
            if twice_area > 0.0:
                n = cross / twice_area
                area = 0.5 * twice_area
                v_rel = wind - (v[a] + v[b] + v[c]) / 3.0
                u = v_rel.dot(n)
                vt = v_rel - u * n
                force = area * (params[8] * u * abs(u) * n + params[10] * vt.norm() * vt
                                + params[9] * abs(u) * vt)
                for q in ti.static(range(3)):
                    f_out[triangles[k][q]] += force / 3.0
