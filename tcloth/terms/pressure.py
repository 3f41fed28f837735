"""Pressure: the gas enclosed by a closed cloth (a balloon, a cushion), isothermal.

Each closed cloth is a chamber holding a fixed amount of ideal gas at constant temperature
(Boyle: P V = P0 V0) in ambient air at pressure P_a. With V the volume its triangles
enclose, x_a . (x_b x x_c) / 6 summed over them (outward winding), its potential is

    U(V) = -P0 V0 ln(V / V0) + P_a (V - V0),

and the force on particle i is (P0 V0 / V - P_a) dV/dx_i, with dV/dx_a = x_b x x_c / 6 from
each triangle (a, b, c) around it: the net pressure P(V) - P_a times a third of the
area-weighted normals. The forces of a chamber sum to zero, as do their torques. P0 - P_a
is the ``pressure`` given at the rest volume V0 (by default the volume of the scene's
positions). Blender and Houdini Vellum give cloth a pressure of this kind.

Backward Euler, projective, VBD and XPBD take it at the start of the step (its Hessian
couples every particle of a chamber).
"""
import numpy as np
import taichi as ti

from ..errors import SceneError
from ..runtime import serial
from ..validate import as_scalar
from .base import Feature, Term


def enclosed_volume(x, triangles):
    """The volume (m^3) that triangles (T,3) enclose at positions x (N,3), NumPy, f64."""
    a, b, c = (np.asarray(x, dtype=np.float64)[triangles[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->", a, np.cross(b, c)) / 6.0)


def gas_table(settings):
    """(chambers, 3) f64: each chamber's P0 V0 (J), P_a (Pa) and V0 (m^3)."""
    v0 = np.abs(settings["rest_volume"])
    return np.stack([(settings["pressure"] + settings["ambient"]) * v0,
                     np.full(len(v0), settings["ambient"]), v0], 1)


def potential(gas, volume):
    """-P0 V0 ln(V / V0) + P_a (V - V0) summed over chambers at volumes V (J)."""
    return float(np.sum(-gas[:, 0] * np.log(volume / gas[:, 2])
                        + gas[:, 1] * (volume - gas[:, 2])))


def closed_surface(triangles, name):
    """Check that triangles (T,3) close a surface: every edge in exactly two triangles,
    once in each direction (consistently wound)."""
    directed = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]],
                               triangles[:, [2, 0]]])
    forward = {tuple(e) for e in directed.tolist()}
    if len(forward) != len(directed):
        raise SceneError(f"{name} is not a consistently wound surface: an edge runs the same "
                         "way in two of its triangles")
    open_edges = [e for e in forward if (e[1], e[0]) not in forward]
    if open_edges:
        raise SceneError(f"{name} does not enclose a volume: {len(open_edges)} edges have one "
                         f"triangle only (e.g. particles {open_edges[0]})")


class PressureFeature(Feature):
    """``Scene.set_pressure``: one chamber per closed cloth; the model's triangles (wound
    outward), their chambers and each chamber's (P0 V0, P_a)."""
    name, method = "pressure", "set_pressure"

    def set(self, scene, pressure, ambient=101325.0, cloths=None, rest_volume=None):
        """Fill closed cloths with gas: each is a chamber whose gauge pressure is
        ``pressure`` at its rest volume and follows Boyle's law (isothermal ideal gas)
        as its volume changes (``tcloth.terms.pressure``).

        Args:
            pressure: gauge pressure P0 - P_a at the rest volume, Pa (> -ambient).
            ambient: the outside air's pressure P_a, Pa >= 0 (default 101325: sea level).
            cloths: indices into ``scene.cloths`` of the chambers (default: every cloth);
                each must be closed (every edge in two triangles, wound consistently).
            rest_volume: None (each chamber's volume at the scene's positions), or one
                volume per chamber, m^3 > 0.
        Returns:
            dict of the settings.
        """
        ambient = as_scalar("ambient", ambient, minimum=0.0)
        pressure = as_scalar("pressure", pressure)
        if pressure + ambient <= 0.0:
            raise SceneError(f"pressure must be above -ambient = {-ambient} Pa (the gas's "
                             f"absolute pressure is positive; got {pressure})")
        count = len(scene.cloths)
        ids = list(range(count)) if cloths is None else [int(c) for c in np.ravel(cloths)]
        if not ids or len(set(ids)) != len(ids) or min(ids) < 0 or max(ids) >= count:
            raise SceneError(f"cloths must be distinct indices into the scene's {count} cloths "
                             f"(got {cloths!r})")
        x, volumes = scene.positions, []
        for k in ids:
            closed_surface(scene.cloths[k].triangles, f"cloth {k}")
            volumes.append(enclosed_volume(x, scene.cloths[k].triangles))
        if rest_volume is not None:
            given = np.ravel(np.asarray(rest_volume, dtype=np.float64))
            if given.shape != (len(ids),) or not np.all(given > 0):
                raise SceneError(f"rest_volume must be {len(ids)} volume(s) > 0, m^3 "
                                 f"(got {rest_volume!r})")
            volumes = [float(v) for v in given]
        for k, v in zip(ids, volumes):
            if abs(v) < 1e-12:
                raise SceneError(f"cloth {k} encloses no volume (|V| = {abs(v):.3g} m^3)")
        return {"pressure": pressure, "ambient": ambient, "cloths": ids,
                "rest_volume": np.array(volumes)}

    def build(self, model, settings):
        """Triangles wound outward (a chamber wound inward is turned over), their chamber
        ids and each chamber's (P0 V0, P_a, V0) as fields (f64)."""
        scene, x = model.scene, model.scene.positions
        tris, chamber = [], []
        for c, k in enumerate(settings["cloths"]):
            t = scene.cloths[k].triangles
            if enclosed_volume(x, t) < 0:
                t = t[:, ::-1]
            tris.append(t)
            chamber.append(np.full(len(t), c))
        tris, chamber = np.concatenate(tris), np.concatenate(chamber)
        model.pressure_triangles = ti.Vector.field(3, ti.i32, shape=len(tris))
        model.pressure_triangles.from_numpy(tris.astype(np.int32))
        model.pressure_chamber = ti.field(ti.i32, shape=len(tris))
        model.pressure_chamber.from_numpy(chamber.astype(np.int32))
        gas = gas_table(settings)
        model.pressure_gas = ti.Vector.field(3, ti.f64, shape=len(gas))
        model.pressure_gas.from_numpy(gas)
        return settings

    def floor(self, settings, scene):
        """The potential's least value (J): U is least at V = P0 V0 / P_a; None (no
        floor) without ambient pressure."""
        if settings["ambient"] == 0.0:
            return None
        gas = gas_table(settings)
        return potential(gas, gas[:, 0] / gas[:, 1])


@ti.kernel
def _volumes(term: ti.template(), x: ti.template()):
    term.chamber_volumes(x)


@ti.data_oriented
class Pressure(Term):
    """The enclosed gas of the scene's chambers (``Scene.set_pressure``)."""
    name = "pressure"
    feature = PressureFeature()

    @staticmethod
    def present(model):
        return model.pressure is not None

    def __init__(self, model):
        self.tris, self.chamber = model.pressure_triangles, model.pressure_chamber
        self.gas = model.pressure_gas
        self.volume = ti.field(ti.f64, shape=self.gas.shape[0])

    def batch_obstacle(self):
        if not serial(self.tris):
            return f"the pressure's {self.tris.shape[0]} triangles run on several threads"
        return None

    @ti.func
    def chamber_volumes(self, x):
        """Each chamber's volume into ``volume`` (f64)."""
        tris, chamber, volume = ti.static(self.tris, self.chamber, self.volume)
        ti.loop_config(serialize=ti.static(serial(volume)))
        for c in range(volume.shape[0]):
            volume[c] = 0
        ti.loop_config(serialize=ti.static(serial(tris)))
        for k in range(tris.shape[0]):
            a, b, c = x[tris[k][0]], x[tris[k][1]], x[tris[k][2]]
            volume[chamber[k]] += ti.cast(a.dot(b.cross(c)) / 6.0, ti.f64)

    @ti.func
    def accumulate(self, x, v, t, f_out):
        """Each chamber's volume, then (P0 V0 / V - P_a) dV/dx on every triangle's corners."""
        tris, chamber, gas, volume = ti.static(self.tris, self.chamber, self.gas, self.volume)
        self.chamber_volumes(x)
        ti.loop_config(serialize=ti.static(serial(tris)))
        for k in range(tris.shape[0]):
            i = tris[k]
            g = gas[chamber[k]]
            p = ti.cast(g[0] / volume[chamber[k]] - g[1], float)
            for j in ti.static(range(3)):
                b, c = x[i[(j + 1) % 3]], x[i[(j + 2) % 3]]
                f_out[i[j]] += p * b.cross(c) / 6.0

    def energy(self, x, t, out):
        """-P0 V0 ln(V / V0) + P_a (V - V0) summed over the chambers, in f64."""
        _volumes(self, x)
        return potential(self.gas.to_numpy(), self.volume.to_numpy())
