"""``Scene.limit_strain`` and the model's limited springs (``tcloth.constraints`` has the
strain limiter that applies it after every step)."""
import numpy as np
import taichi as ti

from ..errors import SceneError
from ..scene.scene import KIND_CODE, SPRING_KINDS
from ..validate import as_int, as_scalar, fmt
from .base import Feature


class StrainLimitData:
    """The model's strain limit (``model.strain_limit``).

    Attributes:
        count: the number of limited springs L.
        index: (max(L, 1),) i32: the model rows (``Model.spring_order``) of the limited
            springs.
        max_stretch: the longest stretch allowed (0.1 = 10 %). iterations: passes a step.
    """

    def __init__(self, rows, max_stretch, iterations):
        self.count = len(rows)
        self.index = ti.field(ti.i32, shape=max(len(rows), 1))
        if len(rows):
            self.index.from_numpy(rows)
        self.max_stretch, self.iterations = max_stretch, iterations


class StrainLimitFeature(Feature):
    """``Scene.limit_strain``; the model's ``StrainLimitData``."""
    name, method = "strain_limit", "limit_strain"

    def set(self, scene, max_stretch=0.1, iterations=20, kinds=("structural", "shear"),
            springs=None):
        """Provot (1995) strain limiting, applied after every step.

        Limited springs longer than (1 + max_stretch) rest length are shortened by moving
        their ends (inverse-mass weighted: a pinned end stays put), ``iterations`` Jacobi
        passes in parallel; velocities get the same correction divided by dt.

        Args:
            max_stretch: > 0 (0.1 = 10 %). iterations: passes per step, >= 1.
            kinds: the spring kinds limited (default structural and shear).
            springs: None, or spring ids to limit instead of whole kinds.
        """
        if springs is None:
            if isinstance(kinds, str) or not kinds or any(k not in KIND_CODE for k in kinds):
                raise SceneError(f"kinds must be a non-empty tuple of {SPRING_KINDS} "
                                 f"(got {kinds!r})")
            ids = np.flatnonzero(np.isin(scene.springs["kind"], [KIND_CODE[k] for k in kinds]))
        else:
            ids = np.asarray(springs)
            if ids.ndim != 1 or ids.dtype.kind not in "iu" or len(ids) == 0 or \
                    ids.min() < 0 or ids.max() >= scene.num_springs:
                raise SceneError(f"springs must be a 1-D array of spring ids in "
                                 f"[0, {scene.num_springs}) (got {fmt(springs)})")
        return {"max_stretch": as_scalar("max_stretch", max_stretch, 0.0, strict=True),
                "iterations": as_int("iterations", iterations, 1),
                "springs": np.unique(ids)}

    def build(self, model, limit):
        """The limited springs' model rows (``StrainLimitData``)."""
        position = np.empty(len(model.spring_order), dtype=np.int64)
        position[model.spring_order] = np.arange(len(model.spring_order))  # scene id -> row
        rows = position[limit["springs"]].astype(np.int32)
        return StrainLimitData(rows, limit["max_stretch"], limit["iterations"])


STRAIN_LIMIT = StrainLimitFeature()
