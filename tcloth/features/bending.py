"""``Scene.set_bending`` and the model's hinges (``tcloth.terms.bending`` has the model of
bending that the hinges carry)."""
import numpy as np
import taichi as ti

from .. import runtime
from ..geometry.graph import element_fields
from ..scene.hinges import cloth_hinge_parts, cloth_hinges, hinge_weights
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
        K, area, share, cloth, family: NumPy, per hinge (``scene.hinges.cloth_hinge_parts``;
            cloth: its cloth's row in the settings), from which ``scaled`` makes c at
            any rigidities: B_e = share * rigidity[cloth, family].
        held: (H,) bool NumPy: the hinges whose two triangles hold (``hold``: a tear cut
            the others, whose c is 0).
    """

    def __init__(self, ids, parts, rigidity, n):
        self.ids = ids
        self.K, self.area, self.share, self.cloth, self.family = parts
        self.held = np.ones(len(ids), dtype=bool)
        self.count = len(ids)
        weights = self.scaled(rigidity)
        self.hinges, self.weights, self.start, self.entries = element_fields(ids, n, weights)
        self.diagonal = ti.field(runtime.real(), shape=n)
        self._set_diagonal(weights)

    def scaled(self, rigidity):
        """The weights c ((H, 4) NumPy) at rigidities ``rigidity`` ((cloths, 2), N m)."""
        rigidity = np.asarray(rigidity, dtype=np.float64)[self.cloth, self.family]
        return hinge_weights(self.K, self.area, self.share, rigidity) * self.held[:, None]

    def hold(self, torn, rigidity):
        """Bend only at the hinges none of whose particle pairs is in ``torn`` ((B, 2)
        particle pairs whose springs broke): the others, one of whose triangles a tear
        cut, get c = 0; at rigidities ``rigidity``."""
        n = int(max(self.ids.max(initial=0), np.max(torn, initial=0))) + 1
        cut = np.sort(np.asarray(torn, dtype=np.int64).reshape(-1, 2), axis=1)
        keys = cut[:, 0] * n + cut[:, 1]
        self.held = np.ones(len(self.ids), dtype=bool)
        for a, b in ((0, 1), (0, 2), (1, 2), (0, 3), (1, 3)):     # the two triangles' edges
            edge = np.sort(self.ids[:, [a, b]], axis=1)
            self.held &= ~np.isin(edge[:, 0] * n + edge[:, 1], keys)
        self.set_rigidity(rigidity)

    def set_rigidity(self, rigidity):
        """The weights and the diagonal at rigidities ``rigidity`` ((cloths, 2), N m)."""
        weights = self.scaled(rigidity)
        if self.count:
            self.weights.from_numpy(weights.astype(runtime.numpy_real()))
        self._set_diagonal(weights)

    def _set_diagonal(self, weights):
        """diagonal = each particle's sum of c^2 over its hinges, for the weights c."""
        n = self.diagonal.shape[0]
        diagonal = np.bincount(self.ids.ravel(), weights=(weights ** 2).ravel(), minlength=n)
        self.diagonal.from_numpy(diagonal.astype(runtime.numpy_real()))


class BendingFeature(Feature):
    """``Scene.set_bending``: the cloths with hinge bending, their rigidities and rest
    positions; the model's ``BendingData``; live (the rigidities: ``Simulator.set_feature``
    changes them, the hinges stay)."""
    name, method, live = "bending", "set_bending", True

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
        scene, rest, parts = model.scene, settings["rest_positions"], []
        for row, k in enumerate(settings["cloths"]):
            ids, K, area, family, share = cloth_hinge_parts(scene.cloths[k], rest)
            parts.append((ids, K, area, share, np.full(len(ids), row), family))
        ids, K, area, share, rows, family = (np.concatenate(z) for z in zip(*parts))
        return BendingData(ids.astype(np.int64), (K, area, share, rows, family),
                           settings["rigidity"], model.particle_count)

    def refresh(self, data, settings):
        """The hinges' weights at the settings' rigidities."""
        data.set_rigidity(settings["rigidity"])


BENDING = BendingFeature()
