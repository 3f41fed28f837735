"""Strain limiting after Provot 1995 ("Deformation constraints in a mass-spring model").

After a step, every limited spring longer than (1 + max_stretch) rest length is shortened
back to that length by moving its ends, weighted by inverse mass (a pinned end stays put).
Corrections of one pass are computed for all springs in parallel and averaged per particle
(Jacobi); ``iterations`` passes. Velocities get the position change divided by dt, so the
state stays consistent with the corrected motion.
"""
import numpy as np
import taichi as ti

from . import runtime
from .errors import SceneError
from .integrators.linalg import copy
from .runtime import serial
from .scene import KIND_CODE, SPRING_KINDS
from .terms.base import Feature
from .validate import as_int, as_scalar, fmt


class StrainLimitFeature(Feature):
    """``Scene.limit_strain``; the model's ``limit_index`` (model rows of the limited
    springs) and ``limit_count``."""
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
        position = np.empty(len(model.spring_order), dtype=np.int64)
        position[model.spring_order] = np.arange(len(model.spring_order))  # scene id -> row
        idx = position[limit["springs"]].astype(np.int32)
        model.limit_count = len(idx)
        model.limit_index = ti.field(ti.i32, shape=max(len(idx), 1))
        if len(idx):
            model.limit_index.from_numpy(idx)
        return limit


STRAIN_LIMIT = StrainLimitFeature()


@ti.kernel
def _limit_pass(limiter: ti.template(), x: ti.template()) -> ti.i32:
    return limiter.limit_pass(x)


@ti.kernel
def _correct_velocities(limiter: ti.template(), state: ti.template(), inv_dt: float):
    limiter.correct_velocities(state, inv_dt)


@ti.data_oriented
class StrainLimiter:
    """The model's strain limit with its scratch (corrections, hit counts, the positions
    before the passes). ``apply`` runs it from Python (a launch a pass); ``limit`` is the
    same as a ``ti.func`` for the simulator's batches of substeps."""

    def __init__(self, model):
        self.model = model
        real, n = runtime.real(), model.particle_count
        self.dx = ti.Vector.field(3, real, shape=n)
        self.hits = ti.field(ti.i32, shape=n)
        self.x_before = ti.Vector.field(3, real, shape=n)
        self.inv_mass, self.pairs, self.rest = model.inv_mass, model.spring_pairs, model.spring_rest
        self.index, self.count = model.limit_index, model.limit_count
        # the longest length over the rest length, rounded as the working precision adds
        real_np = np.dtype(runtime.numpy_real()).type
        self.stretch_factor = float(real_np(1.0) + real_np(model.strain_limit["max_stretch"]))
        self.iterations = model.strain_limit["iterations"]

    def batch_obstacle(self):
        if not serial(self.index):
            return f"strain limiting's {self.count} springs run on several threads"
        return None

    @ti.func
    def limit_pass(self, x):
        """One Jacobi pass; returns how many springs were too long."""
        dx, hits, inv_mass, pairs, rest = ti.static(self.dx, self.hits, self.inv_mass,
                                                    self.pairs, self.rest)
        ti.loop_config(serialize=ti.static(serial(dx)))
        for p in range(dx.shape[0]):
            dx[p] = ti.Vector.zero(float, 3)
            hits[p] = 0
        violated = 0
        ti.loop_config(serialize=ti.static(serial(self.index)))
        for k in range(self.count):
            s = self.index[k]
            i, j = pairs[s][0], pairs[s][1]
            d = x[i] - x[j]
            length = d.norm()
            limit = self.stretch_factor * rest[s]
            wsum = inv_mass[i] + inv_mass[j]
            if length > limit and wsum > 0.0:
                corr = (length - limit) / (length * wsum) * d
                dx[i] -= inv_mass[i] * corr
                dx[j] += inv_mass[j] * corr
                hits[i] += 1
                hits[j] += 1
                violated += 1
        ti.loop_config(serialize=ti.static(serial(dx)))
        for p in range(dx.shape[0]):
            if hits[p] > 0:
                x[p] += dx[p] / hits[p]
        return violated

    @ti.func
    def correct_velocities(self, state, inv_dt):
        ti.loop_config(serialize=ti.static(serial(state.x)))
        for p in range(state.x.shape[0]):
            state.v[p] += (state.x[p] - self.x_before[p]) * inv_dt

    @ti.func
    def limit(self, state, inv_dt):
        """``apply`` as a ``ti.func`` (inv_dt = 1/dt, computed as ``apply`` does)."""
        copy(self.x_before, state.x)
        for _ in range(self.iterations):
            if self.limit_pass(state.x) == 0:
                break
        self.correct_velocities(state, inv_dt)

    def apply(self, state, dt):
        """Apply the strain limit to ``state`` in place. Returns the number of springs
        still too long before the last pass."""
        self.x_before.copy_from(state.x)
        violated = 0
        for _ in range(self.iterations):
            violated = _limit_pass(self, state.x)
            if violated == 0:
                break
        _correct_velocities(self, state, 1.0 / dt)
        return violated
