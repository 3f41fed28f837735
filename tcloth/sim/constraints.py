"""Strain limiting after Provot 1995 ("Deformation constraints in a mass-spring model").

After a step, every limited spring longer than (1 + max_stretch) rest length is shortened
back to that length by moving its ends, weighted by inverse mass (a pinned end stays put).
Corrections of one pass are computed for all springs in parallel and averaged per particle
(Jacobi); ``iterations`` passes. Velocities get the position change divided by dt, so the
state stays consistent with the corrected motion. ``Scene.limit_strain`` and the limited
springs of the model (``model.strain_limit``) are ``features.strain_limit``'s.
"""
import numpy as np
import taichi as ti

from .. import runtime
from ..integrators.linalg import copy
from ..runtime import jacobi_apply, jacobi_zero, serial


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
        limit = model.strain_limit
        self.index, self.count = limit.index, limit.count
        # the longest length over the rest length, rounded as the working precision adds
        real_np = np.dtype(runtime.numpy_real()).type
        self.stretch_factor = float(real_np(1.0) + real_np(limit.max_stretch))
        self.iterations = limit.iterations
        # a torn scene's per-row flags: a broken spring is not limited
        self.torn = model.tearing is not None
        self.alive = model.tearing.alive if self.torn else self.hits

    def batch_obstacle(self):
        if not serial(self.index):
            return f"strain limiting's {self.count} springs run on several threads"
        return None

    @ti.func
    def limit_pass(self, x):
        """One Jacobi pass; returns how many springs were too long."""
        dx, hits, inv_mass, pairs, rest = ti.static(self.dx, self.hits, self.inv_mass,
                                                    self.pairs, self.rest)
        jacobi_zero(dx, hits)
        violated = 0
        ti.loop_config(serialize=ti.static(serial(self.index)))
        for k in range(self.count):
            s = self.index[k]
            i, j = pairs[s][0], pairs[s][1]
            d = x[i] - x[j]
            length = d.norm()
            limit = self.stretch_factor * rest[s]
            wsum = inv_mass[i] + inv_mass[j]
            held = True
            if ti.static(self.torn):
                held = self.alive[s] != 0
            if length > limit and wsum > 0.0 and held:
                corr = (length - limit) / (length * wsum) * d
                dx[i] -= inv_mass[i] * corr
                dx[j] += inv_mass[j] * corr
                hits[i] += 1
                hits[j] += 1
                violated += 1
        jacobi_apply(x, dx, hits)
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
