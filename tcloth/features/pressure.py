"""``Scene.set_pressure`` and the model's chambers (``tcloth.terms.pressure`` has the gas's
potential and how each solver takes it), with the NumPy forms of the chambers' volume and
potential."""
import numpy as np
import taichi as ti

from ..errors import SceneError
from ..geometry.graph import incidence
from ..validate import as_scalar
from .base import Feature


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


class PressureData:
    """The model's pressure (``model.pressure``): its chambers as fields.

    Attributes:
        triangles: (T,) vec3 i32: every chamber's triangles, wound outward.
        chamber: (T,) i32: each triangle's chamber.
        gas: (chambers,) vec3 f64: each chamber's (P0 V0, P_a, V0) (``gas_table``).
        start, entries: each particle's (triangle, slot) pairs in CSR form
            (``graph.incidence``).
    """

    def __init__(self, triangles, chamber, gas, n):
        self.triangles = ti.Vector.field(3, ti.i32, shape=len(triangles))
        self.triangles.from_numpy(triangles.astype(np.int32))
        self.chamber = ti.field(ti.i32, shape=len(triangles))
        self.chamber.from_numpy(chamber.astype(np.int32))
        self.gas = ti.Vector.field(3, ti.f64, shape=len(gas))
        self.gas.from_numpy(gas)
        self.start, self.entries = incidence(triangles, n)


class PressureFeature(Feature):
    """``Scene.set_pressure``: one chamber per closed cloth; the model's ``PressureData``."""
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
        ids and each chamber's (P0 V0, P_a, V0) (``PressureData``)."""
        scene, x = model.scene, model.scene.positions
        tris, chamber = [], []
        for c, k in enumerate(settings["cloths"]):
            t = scene.cloths[k].triangles
            if enclosed_volume(x, t) < 0:
                t = t[:, ::-1]
            tris.append(t)
            chamber.append(np.full(len(t), c))
        return PressureData(np.concatenate(tris), np.concatenate(chamber),
                            gas_table(settings), model.particle_count)

    def floor(self, settings, scene):
        """The potential's least value (J): U is least at V = P0 V0 / P_a; None (no
        floor) without ambient pressure."""
        if settings["ambient"] == 0.0:
            return None
        gas = gas_table(settings)
        return potential(gas, gas[:, 0] / gas[:, 1])


PRESSURE = PressureFeature()
