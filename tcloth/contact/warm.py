"""Compile once: the contact stage's kernels compiled when the simulator is built.

Taichi compiles a kernel at its first launch with each new template argument (a field, a
list, a stage), and a step's contact takes paths that a scene's first frames seldom take:
the proximity list's first rebuild at a step's end, the first swept search, the guard's
planes, projection and fail-safe, the colliders' later sweeps, a mesh collider's
projection, carry and hold. Each one compiled in the middle of a run stalls it for
seconds (15-60 s on two loaded cores for fold's two). ``WarmUp.warm_up`` launches each of
them once, on the fields the simulator's steps will pass, when it is built:

  - the kernels that only read or that write the stage's own columns run on the state as
    it is, with no motion (a rebuild of the proximity list at the start and at the end of
    the step, a swept search, the planes of both lists, their violations);
  - the ones that move particles (the projection, the fail-safe) run on no rows; the
    colliders' sweeps and the mesh colliders' projection and carry run on the state (a
    particle that starts inside a collider can be moved), which is put back after.

Afterwards the step's fields hold what they stop_normal, the proximity list is built again at
the state, and ``stats`` and the mesh colliders' counts are as before: nothing counted,
nothing moved, nothing kept in a gradient's logs (they are off until ``record``).

What this does not cover compiles later: a solver's calls with its own fields
(``search_solve``, ``follow_solve``, ``truncate_solve``, ``begin_hold``: they run in its
first step, but a branch first taken later compiles then), a list that outgrows its capacity (``search.CandidateSearch.fit``
doubles it, and every kernel that reads it compiles again; the capacities are chosen so
that the shipped scenes never do: docs/contact.md, "Compile once"), and a simulator's
switch between batches of substeps and steps from Python after it was built (a live
change).
"""
from . import guard, projection
from .normals import PREDICTED
from .swept import departure, excess, search_step


class WarmUp:
    """``ContactStage``'s warm-up (its attributes are the stage's)."""

    def warm_up(self, steps, x, t0, dt):
        """Compile the kernels ``end_step`` (``batch_finish``) may launch for each step
        (x0, x1, v1) of ``steps`` (the fields the simulator passes), with the state's
        positions x at time t0 and a step of dt; everything put back (module
        docstring)."""
        stats, counts = dict(self.stats), self._counts()
        fields = list({id(f): f for step in steps for f in step}.values())
        saved = [(f, f.to_numpy()) for f in fields]
        here = x.to_numpy()
        for x0, x1, v1 in steps:
            for f in (x0, x1):
                if f is not x:
                    f.from_numpy(here)
            if self.broad is not None:
                self._warm_pairs(x0, x1, v1)
            if self.colliders is not None:
                self._warm_colliders(x0, x1, v1, t0, dt)
        for f, values in saved:
            f.from_numpy(values)
        self.stop_normal.fill(0)
        self.stats = stats
        self._counts(counts)
        self.refresh(x)
        if self.broad is not None:
            self.broad.rebuilds = counts[0]

    def _counts(self, counts=None):
        """(the list's builds, the mesh colliders' searches, their seconds, their hold's
        dropped planes, the mesh fields' fallbacks), set to ``counts`` where given."""
        o, sdf = self.obstacle, self.colliders.sdf if self.colliders is not None else None
        if counts is None:
            return (self.broad.rebuilds if self.broad is not None else 0,
                    o and o.searches, o and o.search_seconds, o and o.hold.dropped,
                    None if sdf is None else int(sdf.fallbacks[None]))
        if o is not None:
            o.searches, o.search_seconds, o.hold.dropped = counts[1:4]
        if sdf is not None:
            sdf.fallbacks[None] = counts[4]
        return counts

    def _warm_pairs(self, x0, x1, v1):
        """The cloth's own pairs on the motion x0 -> x1 (no motion)."""
        broad, swept, thickness = self.broad, self.swept, self.thickness
        broad.build(x1, self.skin)          # the list made to cover a step's end
        broad.build(x0, self.skin)          # and its start (``_step_candidates``)
        broad.covers(x1)
        broad.covers(x0, x1)
        broad.would_cover(x0, x1, self.skin)
        guard.near_planes(broad.candidates, self.planes_of(broad.candidates), broad.count,
                          x0, x1, thickness, broad.ref_gap, broad.far)
        # (a reach or a margin is a kernel's float: any value compiles what the step runs)
        search_step(swept, x0, x1, thickness, thickness)
        points = self.table.points
        excess(points, swept.origin, swept.anchor, x0)
        excess(points, swept.origin, swept.anchor, x1)
        departure(points, swept.origin, swept.anchor, x0, x1)
        for cl, count in ((broad.candidates, broad.count), (swept.candidates, swept.count)):
            pl = self.planes_of(cl)
            for choose in (True, PREDICTED):
                guard.planes(cl, pl, count, x0, x1, thickness, thickness, choose)
            guard.violations(cl, pl, count, x1)
            projection.warm(cl, pl, x1, v1, self.inv_mass, self.stop_normal, self.work, self.log)
            guard.truncate(cl, pl, 0, x0, x1, v1, self.inv_mass, self.cut,
                           self.truncation_log)
        if self.x_swept is not None:
            self.x_swept.copy_from(x1)

    def _warm_colliders(self, x0, x1, v1, t0, dt):
        """The colliders' sweeps of the motion x0 -> x1 (no motion) and the mesh
        colliders' pairs: their search, planes, projection, fail-safe and hold."""
        o = self.obstacle
        if o is not None:
            o.begin(x0, x1, t0, dt, o.thickness)
        self._sweep(x0, x1, v1, t0, dt, True)
        self._sweep(x0, x1, v1, t0, dt, False)
        if self.x_swept is not None:
            self._sweep(self.x_swept, x1, v1, t0 + dt, 0.0, False, obstacle=False)
        if o is not None:
            o.violations(x1)
            o.carry(x0, x1, v1, t0, dt, 1)
            o.hold.begin(o.rows, 0, dt)
            o.hold.end()
