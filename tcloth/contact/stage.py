"""The contact stage: one per simulator, the contact set every consumer reads, and the
guarantee that no step takes cloth through cloth or a particle into a collider.

The ``Simulator`` builds it (``Simulator.contact``) for a scene with self-collision or
colliders and hands it to its integrator, the one object through which a solver takes
contact inside its step (``solve.py``: ``search_solve``, ``follow_solve``, ``keep_apart``,
``detect_bounds``, the hold). It is updated only at named points:

  - ``warm_up(steps, x, t0, dt)``: once, when the simulator is built: every kernel
    ``end_step`` may launch compiled then, not in a later frame (``warm.py``).
  - ``refresh(x)``: after the state was set from outside (``set_state``, ``reset``, a
    checkpoint, the simulator's start): the proximity list covers x.
  - ``end_step(x0, x1, v1, t0, dt)``: after the integrator and the strain limit: the
    guard (``guard.py``) on the step's motion from x0 to x1, over the proximity list
    where it covers that motion, else over the step's swept-box candidates
    (``swept.py``); then the colliders; then, where pairs are still too close, the
    fail-safe. Afterwards the proximity list covers x1 (rebuilt at x1 if not, with
    the default skin).
  - ``search_solve`` / ``follow_solve`` and ``detect_bounds``: called by a solver inside
    its step (``solve.py``); ``detect_bounds`` builds the proximity list again where it
    has grown stale for the bounds (the one rebuild inside a solve, and the stage's own).
  - ``record(on)``: a gradient's runs keep each step's projection corrections and the
    solver's end of the step (``tcloth/grad/frozen.py``).
  - ``batch_begin`` / ``batch_end`` (``ti.func``s of a batch of substeps' kernel,
    ``sim/batch.py``): ``end_step``'s colliders' sweep and, with self-collision, its check
    of the pairs where it finds nothing to do; a step that needs more ends the batch,
    and ``batch_finish`` does the rest of ``end_step`` for it from Python.
So the proximity list covers the current state (a rebuild at most once a step, but for
``detect_bounds``), and the self-contact term (explicit forces, backward Euler's
potential and Hessian, projective's projection) and the diagnostics read it; only the
stage builds it, at these points, and never inside an ``energy()``. A step's force
evaluations away from its start (Runge-Kutta stages, Newton iterates) see the pairs near
the start; what they miss, the guard catches.

``stats`` (``Simulator.contact_stats``): see ``STATS``.
"""
import time

import taichi as ti

from .. import runtime
from . import guard, projection
from .batching import BatchSteps
from .broad import BroadPhase
from .obstacle import ObstaclePairs
from .solve import FAR, OBSTACLE_MARGIN, SolveContact
from .swept import SweptSearch, search_step
from .warm import WarmUp

SWEEPS = 20          # sweeps of the pairs' projection a round (projection.project)
ROUNDS = 4           # rounds of the projection and the colliders' sweep before the fail-safe
GUARD_MARGIN = 0.5   # the swept boxes' margin for the guard's moves, in thicknesses
STATS = {
    "candidates": "rows of the proximity list (pairs within thickness + skin)",
    "rebuilds": "builds of the proximity list so far",
    "swept_searches": "steps whose motion needed the swept-box search",
    "guard_corrections": ("vertex pairs the guard found closer than their planes allow "
                          "(at each round's start) and moved apart, so far"),
    "guard_sweeps": "sweeps of the guard's projection so far (projection.project)",
    "failsafe_steps": "steps that needed the fail-safe (cuts conserve no momentum)",
    "failsafe_vertices": "vertex paths the fail-safe cut short so far",
    "collider_paths_cut": "particle paths that entered a collider and were stopped",
    "obstacle_pairs": "rows of the mesh colliders' pair list (obstacle.py)",
    "obstacle_searches": "searches of the mesh colliders' pairs so far",
    "obstacle_search_seconds": "wall time of those searches so far (the broad phase's)",
    "obstacle_corrections": "cloth vertices the mesh colliders' planes moved so far",
    "hold_steps": ("steps whose solver iterated again to pull the cloth onto the mesh "
                   "colliders' planes (hold.py)"),
    "hold_dropped": ("planes past a cloth vertex's hold.SLOTS, left to the guard, so "
                     "far"),
    "obstacle_carried": ("cloth vertices the mesh colliders' fail-safe carried with the "
                         "obstacle so far"),
    "sdf_fallbacks": ("queries of a mesh collider's distance field beyond its band that the "
                      "exact mesh answered within the caller's reach, so far (motion "
                      "beyond the band: geometry/sdf.py)"),
    "solve_searches": ("candidate searches for solvers' iterations (one at a step's start "
                       "where the proximity list does not cover its predicted motion, and "
                       "again where an iterate left what was searched)"),
    "seconds": ("wall time spent in the stage so far (outside batch kernels, which run "
                "the colliders' sweep inside)"),
}


@ti.data_oriented
class ContactStage(SolveContact, BatchSteps, WarmUp):
    """The contact set and the guard of one simulator (module docstring).

    Attributes:
        table: the model's ``topology.SelfCollisionTable`` or None.
        broad: the proximity list (``broad.BroadPhase``) or None without self-collision.
        colliders: the model's ``collider_table.ColliderTable`` or None without colliders.
        x_start: the step's start positions where a batch of substeps needs them.
        batch_cuts: (paths the collider sweep cut inside batches, in their last step).
        obstacle: the mesh colliders' pairs (``obstacle.ObstaclePairs``) or None.
    """

    def __init__(self, model, primitives=None):
        self.model = model
        self.table = model.self_collision
        self.colliders = model.colliders if model.colliders.count else None
        self.inv_mass = model.inv_mass
        n, real = model.particle_count, runtime.real()
        self.broad = self.swept = None
        if self.table is not None:
            self.broad = BroadPhase(self.table, model.inv_mass, n)
            self.swept = SweptSearch(self.table, model.inv_mass)
            self.thickness = float(self.table.settings["thickness"])
            self.skin = float(self.table.settings["skin"])
            self.cut = ti.field(real, shape=n)
            # the projection's Jacobi passes on GPUs: a particle's corrections and their sum
            self.work = (ti.field(ti.i32, shape=n), ti.Vector.field(3, real, shape=n))
            self.log = projection.Log(1)        # its full size once ``record`` is on
            self.truncation_log = guard.TruncationLog(1, n)
            self.solve_cuts = guard.TruncationLog(1, n)     # a solve's (never kept)
        # the solver's end of the step, kept by ``end_step`` while ``record`` is on, and
        # the cuts of its first collider sweep
        self.solved, self.recording = None, False
        self.truncated = None
        self.sweep_log = guard.SweepLog(1) if self.colliders else None
        # x1 after the step's first collider sweep, where later sweeps start
        self.x_swept = ti.Vector.field(3, real, shape=n) \
            if self.colliders and self.table is not None else None
        self.x_start = (ti.Vector.field(3, real, shape=n)
                        if self.colliders or self.table is not None else None)
        # the collider's outward normal where it stopped a particle's path this step, else 0
        self.stop_normal = ti.Vector.field(3, real, shape=n)
        # paths the collider sweep cut inside batches of substeps: in all, in the last step
        self.batch_cuts = ti.field(ti.i32, shape=2)
        self.stats = {key: 0 for key in STATS}
        self.stats["seconds"] = 0.0
        self.solve_list = None      # the list a solve reads (``search_solve``), or None
        self.solve_near = self.solve_surface = False    # ``search_solve``'s options
        self._planes = {}           # the guard's ``Planes`` beside each list, by its owner
        self.obstacle = None
        if self.colliders is not None and self.colliders.meshes is not None \
                and self.colliders.certified:
            meshes = self.colliders.mesh_colliders
            self.obstacle = ObstaclePairs(model, primitives, max(
                meshes[m]["thickness"] for m in self.colliders.certified))

    # -- the proximity list ------------------------------------------------------------------
    candidates = property(lambda self: self.broad.candidates)
    count = property(lambda self: self.broad.count)

    def refresh(self, x):
        """Make the proximity list cover x (after the state was set from outside)."""
        if self.broad is not None:
            self.broad.invalidate()
            self._cover(x)

    def _cover(self, x):
        if not self.broad.covers(x):
            self.broad.build(x, self.skin)

    @property
    def proximity_planes(self):
        """``planes_of`` the proximity list."""
        return self.planes_of(self.broad.candidates)

    def planes_of(self, cl):
        """The guard's columns (``guard.Planes``) beside list cl, the proximity list or
        the swept one, made again where the list grew."""
        owner = "proximity" if cl is self.broad.candidates else "swept"
        planes = self._planes.get(owner)
        if planes is None or planes.capacity != cl.capacity:
            planes = self._planes[owner] = guard.Planes(cl.capacity)
        return planes

    # -- the guard ---------------------------------------------------------------------------
    def record(self, on):
        """Keep what a gradient takes of each step's guard (``tcloth/grad/frozen.py``):
        the projection's corrections in order (``log``), the cuts of the first collider
        sweep (``sweep_log``) and of the fail-safe (``truncation_log``, and the motion it
        cut: ``truncated``), and the step's end as the solver left it (``solved``: x1,
        v1), from the next ``end_step`` on (a batch of substeps keeps none of them)."""
        if on and self.solved is None:
            n, real = self.model.particle_count, runtime.real()
            self.solved = tuple(ti.Vector.field(3, real, shape=n) for _ in range(2))
            if self.broad is not None:
                self.log = projection.Log()
                self.truncation_log = guard.TruncationLog(n, n)
                self.truncated = tuple(ti.Vector.field(3, real, shape=n) for _ in range(2))
            if self.colliders is not None:
                self.sweep_log = guard.SweepLog(n)
        for log in self._logs():
            log.on[None] = int(on)
        self.recording = bool(on)

    def _logs(self):
        """The logs ``record`` keeps: the projection's and the fail-safe's (with
        self-collision), the first collider sweep's (with colliders)."""
        logs = [self.log, self.truncation_log] if self.broad is not None else []
        return logs + ([self.sweep_log] if self.sweep_log is not None else [])

    def end_step(self, x0, x1, v1, t0, dt):
        """The guard on the motion x0 -> x1 (v1 changed with x1); afterwards the proximity
        list covers x1. Returns whether it changed x1 and v1.

        Where no candidate is too close at x1 and no path enters a collider (most steps
        of an explicit integrator), that is one pass over the candidates and one over the
        particles. Else rounds of the pairs' projection and the colliders' sweep, in which
        a particle a collider stopped moves only along its surface (the collider takes
        the rest), until the projection corrects nothing or the sweep cuts nothing new,
        at most ROUNDS. The first sweep follows the integrator's paths from x0; later
        ones the projection's moves from where the first left x1 (a path that the
        projection pushed into a collider is cut where it entered, not back near x0).
        Then the fail-safe where a pair of the candidates of the final motion is still
        too close, and a last sweep along the paths from x0 (its cuts move particles
        back along them, which keeps every pair on its side)."""
        start = time.perf_counter()
        changed = 0
        if self.recording:
            for log in self._logs():
                log.count[None] = 0
            self.solved[0].copy_from(x1)
            self.solved[1].copy_from(v1)
        if self.obstacle is not None:
            self.obstacle.begin(x0, x1, t0, dt, OBSTACLE_MARGIN * self.obstacle.thickness)
        if self.broad is None:
            changed = self._sweep(x0, x1, v1, t0, dt, True)
        else:
            changed = self._guard_pairs(x0, x1, v1, t0, dt, self._sweep(x0, x1, v1, t0, dt,
                                                                        True))
        if self.obstacle is not None:
            changed += self._obstacle_failsafe(x0, x1, v1, t0, dt)
        self.stats["seconds"] += time.perf_counter() - start
        return changed > 0

    def _guard_pairs(self, x0, x1, v1, t0, dt, cut):
        """``end_step``'s guard of the cloth's own pairs after the colliders' first sweep,
        which cut ``cut`` paths; returns how much it and they changed."""
        changed = cut
        cl, count, covered = self._step_candidates(x0, x1, near=True)
        if cut or guard.violations(cl, self.planes_of(cl), count, x1):
            if covered:     # the rounds and the fail-safe take every row's plane
                guard.planes(cl, self.planes_of(cl), count, x0, x1, self.thickness, FAR, True)
            if self.x_swept is not None:     # x1 as the first sweep left it
                self.x_swept.copy_from(x1)
            changed = cut + self._resolve(cl, count, x0, x1, v1, t0, dt)
        if changed or not covered:
            self._cover(x1)
        self.solve_list = None
        return changed

    def _obstacle_failsafe(self, x0, x1, v1, t0, dt):
        """Where a mesh collider's planes are still not met at x1, its fail-safe (cloth
        vertices carried with it, ``ObstaclePairs.carry``); the vertices carried. Its
        planes are computed again unless they are the motion's as it now is (the cloth's
        own pairs' projection moves particles after them)."""
        if self.broad is not None or not self.obstacle.current:
            self.obstacle.cover(x0, x1, t0, dt, OBSTACLE_MARGIN * self.obstacle.thickness)
        carried = 0
        if self.obstacle.violations(x1):
            self.stats["failsafe_steps"] += 1
            carried = self.obstacle.carry(x0, x1, v1, t0, dt)
            self.stats["obstacle_carried"] += carried
        return carried

    def _resolve(self, cl, count, x0, x1, v1, t0, dt):
        """The rounds, the fail-safe and the last sweep of ``end_step``; returns how much
        they changed. The projection and the sweep move particles off their paths, where
        they can meet pairs the candidates do not hold: a round whose motion the list no
        longer covers takes the candidates of the motion as it now is."""
        changed = 0
        for round_ in range(ROUNDS):
            if round_:
                cut = self._sweep_moves(x0, x1, v1, t0, dt)
                changed += cut
                cl, count = self._still_covering(cl, count, x0, x1)
                if not cut and not guard.violations(cl, self.planes_of(cl), count, x1):
                    break
            corrected, sweeps = projection.project(cl, self.planes_of(cl), count, x1, v1,
                                                   self.inv_mass, self.stop_normal, SWEEPS,
                                                   self.work, self.log)
            self.stats["guard_corrections"] += corrected
            self.stats["guard_sweeps"] += sweeps
            changed += corrected
        else:
            # the last round's projection can push a particle into a collider
            changed += self._sweep_moves(x0, x1, v1, t0, dt)
            cl, count = self._still_covering(cl, count, x0, x1)
            if guard.violations(cl, self.planes_of(cl), count, x1):
                self.stats["failsafe_steps"] += 1
                if self.recording:          # the motion the fail-safe cuts
                    self.truncated[0].copy_from(x1)
                    self.truncated[1].copy_from(v1)
                cut = int(guard.truncate(cl, self.planes_of(cl), count, x0, x1, v1,
                                         self.inv_mass, self.cut, self.truncation_log))
                self.stats["failsafe_vertices"] += cut
                changed += cut + self._sweep(x0, x1, v1, t0, dt, False)
        return changed

    def _sweep(self, x0, x1, v1, t0, dt, first, obstacle=True):
        """The colliders' sweep (``guard.sweep_colliders``; ``first``: the step's first,
        which forgets who was stop_normal) and, with ``obstacle``, the mesh colliders' planes
        (x0, t0 and dt then the step's); the paths it cut and the vertices it moved."""
        if self.colliders is None:
            return 0
        cut = int(guard.sweep_colliders_kernel(self.colliders, self.inv_mass, x0, x1, v1, t0,
                                               dt, self.stop_normal, first, self.sweep_log))
        self.stats["collider_paths_cut"] += cut
        if self.obstacle is not None and obstacle:
            if cut or not first:        # x1 moved since ``begin`` computed the planes
                self.obstacle.cover(x0, x1, t0, dt, OBSTACLE_MARGIN * self.obstacle.thickness)
            corrected = self.obstacle.project(x0, x1, v1, self.stop_normal, t0, dt, SWEEPS, ROUNDS)
            self.stats["obstacle_corrections"] += corrected
            cut += corrected
        return cut

    def _sweep_moves(self, x0, x1, v1, t0, dt):
        """The colliders' sweep of the guard's moves: from x1 as the step's first sweep
        left it to x1 now, at the step's end, then the whole path from x0 (a move can
        take a path that went round a collider's edge through it) (``_sweep``)."""
        if self.colliders is None:
            return 0
        return (self._sweep(self.x_swept, x1, v1, t0 + dt, 0.0, False, obstacle=False)
                + self._sweep(x0, x1, v1, t0, dt, False))

    def _still_covering(self, cl, count, x0, x1):
        """(list, rows) of ``_step_candidates``: cl while it still holds the motion
        x0 -> x1 (the swept list's planes computed again for it), else searched anew."""
        if cl is self.broad.candidates:
            if self.broad.covers(x0, x1):
                return cl, count
        elif self.swept.holds(x0, x1):
            guard.planes(cl, self.planes_of(cl), count, x0, x1, self.thickness,
                         self.thickness, True)
            return cl, count
        cl, count, _ = self._step_candidates(x0, x1)
        return cl, count

    def _step_candidates(self, x0, x1, near=False):
        """(list, rows, whether it is the proximity list) holding every pair that can come
        within the thickness on the motion x0 -> x1, with their separating planes at x0:
        the proximity list where it covers the motion (then it covers x1 too; built
        again at x0 where the motion is within the skin), else the
        swept search's, grown by GUARD_MARGIN thicknesses for the guard's moves, less the pairs
        that cannot come within the thickness on this motion (``guard.planes``: the
        rounds compute them again for the motion as it then is). ``near``: the proximity
        list's planes only for the rows that can come within the thickness (enough to
        find the violations: ``guard.near_planes``)."""
        covered = self.broad.covers(x0, x1)     # ``broad.far`` is the motion's
        if not covered and self.broad.would_cover(x0, x1, self.skin):
            # a step small against the skin (an explicit integrator's): the list built
            # at x0 covers it and x1, where a swept search and a build at x1 would cost two
            self.broad.build(x0, self.skin)
            self.broad.moved(x0, x1)
            covered = True
        if covered:
            cl, count, reach = self.broad.candidates, self.broad.count, FAR
            if near:
                guard.near_planes(cl, self.planes_of(cl), count, x0, x1, self.thickness,
                                  self.broad.ref_gap, self.broad.far)
                return cl, count, covered
        else:
            reach = self.thickness
            solved = (self.solve_list is not None
                      and self.solve_list[0] is self.swept.candidates)
            if solved and self.swept.holds(x0, x1):      # a solve's search holds the step
                count = self.solve_list[1]
            else:
                self.stats["swept_searches"] += 1
                count = search_step(self.swept, x0, x1, self.thickness,
                                    GUARD_MARGIN * self.thickness)
            cl = self.swept.candidates        # after the search, which may grow the list
        guard.planes(cl, self.planes_of(cl), count, x0, x1, self.thickness, reach, True)
        return cl, count, covered

    def contact_stats(self):
        """A copy of ``stats`` with the current candidate and rebuild counts, and with
        mesh colliders ``mesh_paths``: each one's ``SdfStore.paths`` entry (in the order
        of ``ColliderTable.mesh_colliders``: its path, field or certified pairs, and
        why)."""
        out = dict(self.stats)
        out["collider_paths_cut"] += int(self.batch_cuts[0])
        if self.broad is not None:
            out["candidates"] = self.broad.count
            out["rebuilds"] = self.broad.rebuilds
        if self.colliders is not None and self.colliders.sdf is not None:
            out["sdf_fallbacks"] = int(self.colliders.sdf.fallbacks[None])
            out["mesh_paths"] = [dict(p) for p in self.colliders.sdf.paths]
        if self.obstacle is not None:
            out["obstacle_pairs"] = self.obstacle.count
            out["obstacle_searches"] = self.obstacle.searches
            out["obstacle_search_seconds"] = self.obstacle.search_seconds
            out["hold_dropped"] = self.obstacle.hold.dropped
        return out

    def reset_stats(self):
        """Start the counts and the time of ``stats`` again from zero (a new run:
        ``Simulator.reset``); the proximity list is kept."""
        self.stats = {key: 0 for key in STATS}
        self.stats["seconds"] = 0.0
        self.batch_cuts.fill(0)
        if self.colliders is not None and self.colliders.sdf is not None:
            self.colliders.sdf.fallbacks.fill(0)
        if self.broad is not None:
            self.broad.rebuilds = 0
        if self.obstacle is not None:
            self.obstacle.searches, self.obstacle.search_seconds = 0, 0.0
            self.obstacle.hold.dropped = 0
