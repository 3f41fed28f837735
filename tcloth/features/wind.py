"""``Scene.set_wind`` and the model's wind triangles and parameters (``tcloth.terms.wind``
has the force: Wejchert & Haumann's quadratic wind), with the wind's velocity at a time."""
import numpy as np
import taichi as ti

from .. import runtime
from ..errors import SceneError
from ..validate import as_scalar, as_vec3
from .base import Feature


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
    """The ``WindData.params`` values of a ``Scene.wind`` dict with this mean velocity."""
    return np.array([*velocity, *wind["amplitude"], wind["frequency"], wind["phase"],
                     wind["drag"], wind["lift"], wind["tangential"]],
                    dtype=runtime.numpy_real())


class WindData:
    """The model's wind (``model.wind``): the cloth triangles it blows on and its numbers.

    Attributes:
        settings: the scene's wind dict (``Scene.set_wind``), the one ``refresh`` was last
            given (its ``callable`` gust is evaluated from Python).
        triangles: (T,) vec3 i32 particle ids of the scene's cloth triangles (one torn
            by ``Scene.set_tearing``: (a, a, a), ``hold``); all_triangles: them in NumPy.
        params: (11,) reals: (velocity (3), gust amplitude (3), frequency, phase, drag,
            lift, tangential) (``pack``).
    """

    def __init__(self, settings, triangles):
        self.settings = settings
        self.triangles = ti.Vector.field(3, ti.i32, shape=len(triangles))
        self.triangles.from_numpy(triangles.astype(np.int32))
        self.params = ti.field(runtime.real(), shape=11)
        self.all_triangles = np.asarray(triangles, dtype=np.int32)

    def hold(self, held):
        """Blow on the triangles ``held`` (T,) bool only (a tear cut the others): the
        others become (a, a, a), of no area, so no force."""
        tris = self.all_triangles.copy()
        tris[~held] = tris[~held, :1]
        self.triangles.from_numpy(tris)


class WindFeature(Feature):
    """``Scene.set_wind``; the model's ``WindData``; live (the mean velocity). A callable
    gust cannot be checkpointed."""
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
            drag: coefficient >= 0, kg/m^3.
            lift: coefficient >= 0, kg/m^3.
            tangential: coefficient >= 0, kg/m^3.
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
        """The cloth triangles and the wind's parameter field (``WindData``; None without
        cloth)."""
        triangles = model.scene.triangles
        if not len(triangles):
            return None
        return WindData(wind, triangles)

    def refresh(self, data, wind):
        """The scene's wind now into ``data``: its dict and the parameters of its mean
        velocity."""
        data.settings = wind
        data.params.from_numpy(pack(wind, wind["velocity"]))


WIND = WindFeature()
