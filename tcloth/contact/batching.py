"""The contact stage inside a batch of substeps (``sim/batch.py``): the colliders' sweep
and the check of the cloth's own pairs as ``ContactStage.end_step`` does them, as
``ti.func``s of the batch's kernel, and from Python the rest of ``end_step`` for a step
the check could not pass (``BatchSteps``, which ``ContactStage`` is)."""
import time

import taichi as ti

from . import guard
from .broad import spread


class BatchSteps:
    """``ContactStage``'s part inside batches of substeps (its attributes are the
    stage's)."""

    @ti.func
    def batch_begin(self, x):
        """A step inside a batch starts at x: kept for ``batch_end``'s sweep."""
        for p in range(x.shape[0]):
            self.x_start[p] = x[p]

    @ti.func
    def batch_end(self, x, v, t, dt):
        """The colliders' sweep (``guard.sweep_colliders``; with self-collision as
        ``end_step``'s first) of the step from ``batch_begin``'s start to x, its cuts
        counted in ``batch_cuts`` (in all, in the last step), then, with self-collision,
        ``end_step``'s check of the pairs as it passes where nothing is to be done (the
        proximity list covers the step and no pair is too close). Returns (how many paths
        the sweep cut, whether the step needs the rest of ``end_step`` from Python:
        ``batch_finish``)."""
        cut = 0
        if ti.static(bool(self.colliders)):
            if ti.static(bool(self.broad)):
                for p in range(self.stop_normal.shape[0]):
                    self.stop_normal[p] = ti.Vector([0.0, 0.0, 0.0])
            cut = guard.sweep_colliders(self.colliders, self.inv_mass, self.x_start, x, v,
                                        t, dt, self.stop_normal, self.sweep_log, False)
            self.batch_cuts[0] += cut
            self.batch_cuts[1] = cut
        unfinished = 0
        if ti.static(bool(self.broad)):
            unfinished = 1
            if cut == 0:
                if self._pairs_pass(x):
                    unfinished = 0
        return cut, unfinished

    @ti.func
    def _pairs_pass(self, x):
        """Whether the proximity list covers the motion from ``batch_begin``'s start to x
        and no pair of it is closer than its plane allows (``_step_candidates`` with
        ``near``, then ``guard.violations``)."""
        passes = False
        if spread(self.broad, self.broad.x_ref, self.x_start, x, True) <= \
                self.broad.skin_now[None]:
            guard.near_plane_rows(self.broad.candidates, self.proximity_planes,
                                  self.broad.rows[None], self.x_start, x, self.thickness,
                                  self.broad.ref_gap, self.broad.far)
            passes = guard.violated_rows(self.broad.candidates, self.proximity_planes,
                                         self.broad.rows[None], x) == 0
        return passes

    def batch_finish(self, x1, v1, t0, dt):
        """The rest of ``end_step`` (after the colliders' first sweep, done in the batch)
        for a batch's step from ``batch_begin``'s start to x1 that ``batch_end`` found
        unfinished; returns whether the step changed x1 and v1 (the sweep included)."""
        start = time.perf_counter()
        cut = int(self.batch_cuts[1])
        changed = self._guard_pairs(self.x_start, x1, v1, t0, dt, cut)
        self.stats["seconds"] += time.perf_counter() - start
        return changed > 0

    def batch_counts(self):
        """The counts of ``stats``, of the batches' collider cuts and of the mesh fields'
        fallbacks as they stand at a batch's start, for ``batch_replay``."""
        return dict(self.stats), int(self.batch_cuts[0]), self._fallbacks(None)

    def batch_replay(self, counts):
        """The counts back to a batch's start (``batch_counts``), whose steps run again
        one at a time (after a bad step): each step is then counted once. The time spent
        (``seconds``) and the list's builds, which were done, stay."""
        stats, cuts, fallbacks = counts
        self.stats = {**stats, "seconds": self.stats["seconds"]}
        self.batch_cuts[0] = cuts
        self._fallbacks(fallbacks)

    def _fallbacks(self, value):
        """The mesh fields' fallback count (None without fields), set to ``value`` unless
        that is None."""
        sdf = self.colliders.sdf if self.colliders is not None else None
        if sdf is None:
            return None
        if value is not None:
            sdf.fallbacks[None] = value
        return int(sdf.fallbacks[None])

    def batch_key(self):
        """The fields a batch's kernel reads that the stage makes again (the proximity
        list and its columns where the list grew): a batch compiled for another key is
        compiled again."""
        if self.broad is None:
            return None
        return self.broad.candidates, self.broad.ref_gap, self.proximity_planes

    def batch_obstacle(self):
        """Why a batch of substeps cannot run this stage's steps, or None."""
        if self.obstacle is not None:
            return "mesh colliders search their pairs between steps"
        if self.colliders is not None and self.colliders.moving:
            return "keyframed mesh colliders are posed from Python before each step"
        return None

    def batch_cut_last(self):
        """Whether the collider sweep cut a path in a batch's last step (its velocities
        then changed after the forces were evaluated)."""
        return self.batch_cuts[1] > 0
