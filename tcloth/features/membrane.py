"""``Scene.set_membrane`` and the model's membrane triangles (``tcloth.terms.membrane`` has
the energy: Baraff & Witkin's stretch and shear conditions)."""
import numpy as np

from .. import runtime
from ..errors import SceneError
from ..geometry.graph import element_fields
from ..validate import as_per_item, as_warp_weft_per
from .base import Feature, cloth_selection


def triangle_frames(triangles, rest):
    """(b (T,3,2), area (T,)) of triangles (T,3) at rest positions (N,3): the weights of
    f_u, f_v (``tcloth.terms.membrane``) and the rest areas. SceneError for a degenerate
    one."""
    tris = np.asarray(triangles, dtype=np.int64)
    e1, e2 = rest[tris[:, 1]] - rest[tris[:, 0]], rest[tris[:, 2]] - rest[tris[:, 0]]
    normal = np.cross(e1, e2)
    double = np.linalg.norm(normal, axis=1)
    scale = max(float(np.max(np.linalg.norm(e1, axis=1), initial=0.0)), 1e-300)
    bad = np.flatnonzero(double <= 1e-12 * scale * scale)
    if len(bad):
        raise SceneError(f"the membrane needs triangles of positive area: triangle "
                         f"{tris[bad[0]].tolist()} is degenerate at its rest positions")
    n = normal / double[:, None]
    u = np.array([1.0, 0.0, 0.0]) - n[:, :1] * n
    faces_x = np.linalg.norm(u, axis=1) < 0.5
    u[faces_x] = np.array([0.0, 1.0, 0.0]) - n[faces_x, 1:2] * n[faces_x]
    u /= np.linalg.norm(u, axis=1)[:, None]
    v = np.cross(n, u)
    D = np.stack([np.stack([np.sum(e1 * u, 1), np.sum(e2 * u, 1)], 1),
                  np.stack([np.sum(e1 * v, 1), np.sum(e2 * v, 1)], 1)], 1)
    # (T, 2, 2); f = [e1 e2] inv: rows weight e1, e2. The adjugate over the determinant in
    # NumPy's elementwise IEEE operations, not np.linalg.inv: LAPACK's kernels round by
    # CPU (OpenBLAS's SkylakeX against Haswell differ in the last bit)
    det = D[:, 0, 0] * D[:, 1, 1] - D[:, 0, 1] * D[:, 1, 0]
    inv = np.stack([np.stack([D[:, 1, 1], -D[:, 0, 1]], 1),
                    np.stack([-D[:, 1, 0], D[:, 0, 0]], 1)], 1) / det[:, None, None]
    b = np.stack([-(inv[:, 0] + inv[:, 1]), inv[:, 0], inv[:, 1]], 1)
    return b, 0.5 * double


class MembraneData:
    """The model's membrane (``model.membrane``): its triangles as fields.

    Attributes:
        count: the number of triangles T.
        triangles: (T,) vec3 i32 particle ids.
        weights: (T,) 3 x 2: each corner's weights b of f_u, f_v (``triangle_frames``).
        coefficients: (T,) vec4: (A C_u, A C_v, A G, beta), A the rest area.
        start, entries: each particle's (triangle, slot) pairs in CSR form
            (``graph.incidence``).
        ids, area, reduced, cloth: NumPy, per triangle: its particle ids, its rest area,
            an edge's reduced mass (a third of the triangle's mass each, halved) and its
            cloth's row in the settings, from which ``coefficients_for`` makes the
            coefficients.
    """

    def __init__(self, ids, weights, area, reduced, cloth, settings, n):
        self.ids, self.area, self.reduced, self.cloth = ids, area, reduced, cloth
        (self.triangles, self.weights, self.coefficients, self.start,
         self.entries) = element_fields(ids, n, weights, self.coefficients_for(settings))
        self.count = len(ids)

    def masses_changed(self, masses):
        """The particles' masses (N,) changed: the reduced masses the damping reads (the
        coefficients follow at the next ``coefficients_for``)."""
        self.reduced = reduced_masses(masses, self.ids)

    def coefficients_for(self, settings):
        """(T, 4) NumPy: each triangle's (A C_u, A C_v, A G, beta) at the settings' stretch,
        shear and damping; beta = 2 zeta sqrt(m_reduced / max(C_u, C_v)), a ratio of
        critical of an edge's two masses against the stiffer stretch."""
        stretch = np.asarray(settings["stretch"], dtype=np.float64)[self.cloth]
        shear = np.asarray(settings["shear"], dtype=np.float64)[self.cloth]
        zeta = np.asarray(settings["damping"], dtype=np.float64)[self.cloth]
        beta = 2.0 * zeta * np.sqrt(self.reduced / stretch.max(axis=1))
        return np.stack([self.area * stretch[:, 0], self.area * stretch[:, 1],
                         self.area * shear, beta], 1)


def reduced_masses(masses, triangles):
    """Each triangle's edge reduced mass: a third of its mass at each corner, halved."""
    return masses[triangles].mean(axis=1) / 2.0


class MembraneFeature(Feature):
    """``Scene.set_membrane``: the cloths with a triangle membrane, their stiffnesses and
    rest positions; the model's ``MembraneData``; live (the stiffnesses and damping:
    ``Simulator.set_feature``; the triangles stay)."""
    name, method, live = "membrane", "set_membrane", True

    def set(self, scene, stretch, shear, damping=0.0, cloths=None, rest_positions=None):
        """Give cloths membrane elasticity on their triangles: stretch stiffness along warp
        and weft and shear stiffness, independent of each other and of the triangles'
        shapes (``tcloth.terms.membrane``: Baraff & Witkin's conditions as an energy).
        Replaces any earlier call; ``add_mesh_cloth(fabric=...)`` adds its cloth to the
        ones set.

        Args:
            stretch: N/m > 0 per width: one number, a (warp, weft) pair (warp along the
                world x axis projected into each triangle), or a (len(cloths), 2) array.
            shear: N/m > 0 per width: one number or one per cloth.
            damping: each condition's damping as a ratio of critical of an edge's two
                masses against the stiffer stretch, >= 0: one number or one per cloth.
            cloths: indices into ``scene.cloths`` (default: every cloth).
            rest_positions: None (the scene's positions now), or (N,3) positions of all
                the scene's particles at which the cloths are unstrained.
        Returns:
            dict of the settings.
        """
        ids, rest = cloth_selection(scene, cloths, rest_positions)
        stretches = as_warp_weft_per("stretch", stretch, len(ids), strict=True)
        shears = as_per_item("shear", shear, len(ids), minimum=0.0, strict=True)
        dampings = as_per_item("damping", damping, len(ids), minimum=0.0)
        for k in ids:
            triangle_frames(scene.cloths[k].triangles, rest)
        return {"stretch": stretches, "shear": shears, "damping": dampings, "cloths": ids,
                "rest_positions": rest}

    def build(self, model, settings):
        """The chosen cloths' triangles, their weights and coefficients at their rest
        positions (``MembraneData``)."""
        scene = model.scene
        rest, masses = settings["rest_positions"], scene.masses
        ids, weights, areas, reduced, rows = [], [], [], [], []
        for row, k in enumerate(settings["cloths"]):
            tris = scene.cloths[k].triangles
            b, area = triangle_frames(tris, rest)
            ids.append(tris)
            weights.append(b)
            areas.append(area)
            reduced.append(reduced_masses(masses, tris))
            rows.append(np.full(len(tris), row))
        return MembraneData(*(np.concatenate(z) for z in (ids, weights, areas, reduced, rows)),
                            settings, model.particle_count)

    def refresh(self, data, settings):
        """The triangles' coefficients at the settings' stiffnesses and damping."""
        data.coefficients.from_numpy(
            data.coefficients_for(settings).astype(runtime.numpy_real()))


MEMBRANE = MembraneFeature()
