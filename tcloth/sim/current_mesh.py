"""The cloth's mesh as it stands during a run, after the seams that welded and the springs
that tore (``CurrentMesh``, which ``Simulator`` is): what the renderer, the viewer and the
exporters draw."""
import numpy as np


class CurrentMesh:
    """``Simulator``'s queries of its mesh now (its attributes are the simulator's:
    ``_welds``, ``_tearing``, ``scene``, ``model``, ``_check``)."""

    def welded(self) -> np.ndarray:
        """(W, 2) the pairs (a, b) of welded seams that have met so far, now one particle
        each (``Scene.sew(..., weld=True)``, ``welds.py``)."""
        self._check()
        return np.zeros((0, 2), np.int64) if self._welds is None else self._welds.welded_pairs()

    def triangles(self) -> np.ndarray:
        """(T, 3) the cloths' triangles with each welded pair's second particle replaced by
        its first: the merged mesh (``Scene.triangles`` before any weld)."""
        tri = self.scene.triangles
        welded = self.welded()
        if not len(welded):
            return tri
        one = np.arange(self.model.particle_count)
        one[welded[:, 1]] = welded[:, 0]
        return one[tri]

    def torn(self) -> np.ndarray:
        """(B,) int64: the scene spring ids that broke so far (``Scene.set_tearing``), in
        the order they did; empty without tearing."""
        self._check()
        return (np.zeros(0, np.int64) if self._tearing is None else self._tearing.torn())

    def surface(self) -> np.ndarray:
        """(T,) bool over ``scene.triangles``: the cloth triangles that hold (all of them
        without tearing; a torn one has a broken spring along an edge)."""
        self._check()
        if self._tearing is None:
            return np.ones(len(self.scene.triangles), dtype=bool)
        return self._tearing.surface()

    @property
    def surface_version(self) -> int:
        """A number that changes whenever ``surface()`` may have (a spring broke)."""
        return 0 if self._tearing is None else self._tearing.version
