"""What a solver takes of contact inside its step (``SolveContact``, which
``ContactStage`` is): the candidates its iterations keep on their separating planes, the
displacement bounds, and the mesh colliders' hold.

  - ``search_solve(x0, x_pred)`` at a step's start and ``follow_solve(x0, x)`` after each
    iteration (XPBD, VBD, projective): the candidates, searched once for the predicted
    motion and again only where an iterate leaves what was searched
    (``stats["solve_searches"]``); ``keep_apart`` moves an iterate's vertex pairs back
    onto their planes; the guard takes the same candidates at the step's end where they
    still hold its motion. ``truncate_solve(x0, x_pred, v)``: the predicted motion cut
    short at those pairs' dividing planes (projective dynamics' first iterate).
  - ``displacement_bounds()`` and ``detect_bounds(bounds, x)`` (VBD's ``bounds=True``):
    how far each particle may move, from the proximity list, at a step's start and after
    an iteration that clamped a move.
  - ``hold``, ``begin_hold(x0, x, t0, dt)``, ``end_hold()``: the mesh colliders' planes
    the step ends below, as a stiff penalty the solver iterates with (``hold.py``).
"""
from . import guard
from .bounds import DisplacementBounds
from .normals import PREDICTED
from .swept import search_step

# the swept boxes' margin for a solve's iterates, in thicknesses
SOLVE_MARGIN = 2.0
# a near search's margin (``SweptSearch.holds``: each particle within it of its searched
# start and end), in thicknesses. Projective on the 64 x 64 fold: a second in 16.0 s at 1
# and 17.0 s at 1.5; on the twisted cloth the guard corrected 7,524 pairs at 1, 3,306 at
# 1.5 and 3,190 at 2 (docs/contact.md)
NEAR_SOLVE_MARGIN = 1.5
OBSTACLE_MARGIN = 0.25  # the obstacle pairs' boxes' margin, in thicknesses
FAR = 1e30           # m: a reach that keeps every candidate of the proximity list


class SolveContact:
    """``ContactStage``'s part that solvers call inside a step (its attributes are the
    stage's)."""

    def search_solve(self, x0, x_pred, near=False, keep_surface=False):
        """The candidates a solver's iterations keep apart on a step from x0 whose
        iterates are predicted to end near x_pred: every pair that can come within the
        thickness on a motion from x0 whose ends lie within SOLVE_MARGIN thicknesses of
        the boxes of x0 and x_pred (the proximity list where it covers that, else a
        swept search), or with ``near`` (a solver whose iterates stay near x_pred) on a
        motion whose particles start within NEAR_SOLVE_MARGIN thicknesses of x0 and end
        within it of x_pred (``swept.py``), with their separating planes at x0
        (``guard.planes``: a pair keeps n . (x_a - x_b) >= delta). Returns (list, its
        planes, rows) as ``keep_apart`` takes them; ``follow_solve`` keeps them
        covering the iterates, and ``end_step`` checks the step with them where they
        still hold it. keep_surface: the planes take the surfaces' normal also where
        the prediction crosses both (``normals.PREDICTED``)."""
        self.solve_near, self.solve_surface = near, keep_surface
        choose = PREDICTED if keep_surface else True
        if self.broad.covers(x0, x_pred):
            cl, count = self.broad.candidates, self.broad.count
        else:
            self.stats["solve_searches"] += 1
            margin = (NEAR_SOLVE_MARGIN if near else SOLVE_MARGIN) * self.thickness
            count = search_step(self.swept, x0, x_pred, self.thickness, margin, near)
            cl = self.swept.candidates
        guard.planes(cl, self.planes_of(cl), count, x0, x_pred, self.thickness, FAR, choose)
        self.solve_list = (cl, count)
        return cl, self.planes_of(cl), count

    def follow_solve(self, x0, x, choose=False):
        """(list, its planes, rows) of ``search_solve`` for the iterate x: the same while
        they hold the motion x0 -> x, else searched again for it; with ``choose``, the
        planes x crosses chosen again for that motion (``guard.choose_again``)."""
        cl, count = self.solve_list
        covered = (self.broad.covers(x0, x) if cl is self.broad.candidates
                   else self.swept.holds(x0, x))
        if covered and choose:
            guard.choose_again(cl, self.planes_of(cl), count, x0, x, self.thickness)
        return ((cl, self.planes_of(cl), count) if covered
                else self.search_solve(x0, x, self.solve_near, self.solve_surface))

    def truncate_solve(self, x0, x_pred, v):
        """The predicted motion of the last ``search_solve``, from x0 to x_pred, cut short
        where it would take a vertex across the dividing plane of one of its candidates
        (``guard.truncate``, the fail-safe's cut: x_pred = x0 + t (x_pred - x0), v scaled
        by t). Returns how many vertices were cut."""
        cl, count = self.solve_list
        return int(guard.truncate(cl, self.planes_of(cl), count, x0, x_pred, v,
                                  self.inv_mass, self.cut, self.solve_cuts))

    def keep_apart(self, x0, x, dx, hits, choose=False):
        """Move the iterate x's vertex pairs of ``follow_solve(x0, x, choose)`` that are
        closer along their plane's normal than its delta apart (``guard.keep_apart``: one
        Jacobi pass; dx, hits: (n,) scratch fields). Returns how many pairs were closer."""
        return guard.keep_apart(*self.follow_solve(x0, x, choose), x, self.inv_mass, dx, hits)

    def displacement_bounds(self):
        """A solver's ``bounds.DisplacementBounds`` for this stage's particles (for
        ``detect_bounds``), or None in a scene without self-collision."""
        return None if self.broad is None else DisplacementBounds(self.inv_mass)

    def detect_bounds(self, bounds, x):
        """A solver's displacement bounds (``bounds.DisplacementBounds``, VBD's
        ``bounds=True``) detected at x, from the proximity list, built again at x first
        where particles moved relative to each other by more than half its reach since
        its build (the balls would shrink towards nothing). Returns whether it built the
        list (its rows changed: what a solver keeps per row is stale)."""
        floor = self.broad.unlisted_distance(x)
        rebuilt = floor < 0.5 * float(self.broad.reach[None])
        if rebuilt:
            self.broad.build(x, self.broad.skin)
            floor = self.broad.unlisted_distance(x)
        bounds.detect(self.broad.candidates, self.broad.count, x, floor)
        return rebuilt

    @property
    def hold(self):
        """The mesh colliders' ``hold.Hold`` (a per-particle potential term a solver
        includes), or None without mesh colliders."""
        return None if self.obstacle is None else self.obstacle.hold

    def begin_hold(self, x0, x, t0, dt):
        """The mesh colliders' pairs and planes for a solver's motion x0 -> x over the
        step (t0, dt), searched where the list does not hold that motion; where a cloth
        vertex ends below one, the hold on (``hold.py``: the solver iterates again with
        the planes as a stiff penalty, then calls ``end_hold``). Returns the rows short of
        their plane (0: the hold stays off)."""
        o = self.obstacle
        o.begin(x0, x, t0, dt, OBSTACLE_MARGIN * o.thickness)
        short = o.violations(x)
        if short:
            o.hold.begin(o.rows, o.count, dt)
            self.stats["hold_steps"] += 1
        return short

    def end_hold(self):
        self.obstacle.hold.end()
