"""``Scene.set_bending`` and the model's hinges (``tcloth.terms.bending`` has the model of
bending that the hinges carry)."""
import numpy as np
import taichi as ti

from .. import runtime
from ..graph import element_fields
from ..scene.hinges import cloth_hinges
from ..validate import as_warp_weft_per
from .base import Feature, cloth_selection


class BendingData:
    """The model's bending (``model.bending``): its hinges as fields.

    Attributes:
        count: the number of hinges H (may be 0: cloths without interior edges).
        hinges: (max(H, 1),) vec4 i32: each hinge's edge (x0, x1) and the opposite vertices
            (x2, x3) of its two triangles.
        weights: (max(H, 1),) vec4 of the hinge's c = sqrt(B_e / A_e) K.
        start, entries: each particle's (hinge, slot) pairs in CSR form
            (``graph.incidence``).
        diagonal: (particle_count,) each particle's sum of c^2 over its hinges.
    """

    def __init__(self, ids, weights, n):
        self.hinges, self.weights, self.start, self.entries = element_fields(ids, n, weights)
        diagonal = np.bincount(ids.ravel(), weights=(weights ** 2).ravel(), minlength=n)
        self.diagonal = ti.field(runtime.real(), shape=n)
        self.diagonal.from_numpy(diagonal.astype(runtime.numpy_real()))
        self.count = len(ids)


class BendingFeature(Feature):
    """``Scene.set_bending``: the cloths with hinge bending, their rigidities and rest
    positions; the model's ``BendingData``."""
    name, method = "bending", "set_bending"

    def set(self, scene, rigidity, cloths=None, rest_positions=None):
        """Give cloths a bending rigidity B (N m): a hinge energy on every interior edge
        of their triangles, B/2 kappa^2 per area at curvature kappa
        (``tcloth.terms.bending``; Bergou et al. 2006's quadratic bending). Replaces any
        earlier call; ``add_cloth(fabric=...)`` adds its cloth to the ones set (``builders``).

        Args:
            rigidity: N m >= 0: one number, a (warp, weft) pair (grid cloths: warp bends
                along the grid's i, weft along j), or a (len(cloths), 2) array of pairs,
                one per cloth.
            cloths: indices into ``scene.cloths`` (default: every cloth).
            rest_positions: None (the scene's positions now), or (N,3) positions of all
                the scene's particles at which the cloths are flat and unbent.
        Returns:
            dict of the settings.
        """
        ids, rest = cloth_selection(scene, cloths, rest_positions)
        rigidities = as_warp_weft_per("rigidity", rigidity, len(ids))
        for k, b in zip(ids, rigidities):
            cloth_hinges(scene.cloths[k], rest, b)
        return {"rigidity": rigidities, "cloths": ids, "rest_positions": rest}

    def build(self, model, settings):
        """The hinges of the chosen cloths at their rest positions (``BendingData``)."""
        scene = model.scene
        parts = [cloth_hinges(scene.cloths[k], settings["rest_positions"], b)
                 for k, b in zip(settings["cloths"], settings["rigidity"])]
        ids = np.concatenate([p[0] for p in parts]).astype(np.int64)
        weights = np.concatenate([p[1] for p in parts])
        return BendingData(ids, weights, model.particle_count)


BENDING = BendingFeature()
