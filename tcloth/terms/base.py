"""What a physics term is, and the kernels shared by per-particle terms.

A term is one module with one class, built from the ``Model`` by each consumer that needs
it (an integrator's workspace, the diagnostics); it reads the model's static fields and
keeps its own scratch. Every term gives:

  - ``present(model)`` (static): whether the scene has it; absent terms are never built,
    so nothing of theirs is compiled or launched;
  - ``accumulate(x, v, t, f_out)`` (a ``ti.func`` with the term's loops): f_out += its
    force at positions x, velocities v and time t. ``Forces`` calls the accumulates of a
    scene's terms in one kernel, and the simulator's batch of substeps calls them all in
    one launch (``batch.py``). A term whose force needs Python between its loops (a
    candidate list that grows) sets ``in_kernel = False`` and gives
    ``add_forces(x, v, t, f_out)`` (kernel launches) instead;
  - ``prepare(t)``: Python work before a force evaluation at time t (an upload);
  - ``batch_obstacle()``: None when its force may run in a batch of substeps without
    Python between them, else the reason why not (one line, for ``Simulator.fusion``);
  - ``energy(x, t, out)``: its potential energy (J, a float), or None when it has none;
  - ``stored(x, t, out)``: (its potential energy or None, the largest strain of its
    elements or None) for the instability test (``budget.py``); the default is
    (``energy``, None), springs and the membrane give their strain from the same pass;
  - ``name``: its key in ``Simulator.energy()``;
  - ``implicit``: how backward Euler takes it: "potential" (its energy, gradient and
    Hessian enter Newton's incremental potential) or "lagged" (its force at the start of
    the step enters as a constant, explicitly);
  - ``projective``: how projective dynamics takes it: "force" (in the force residual of
    every iteration), "lagged" (in Liu's y at the start of the step), "contact" (the
    colliders, which projective dynamics and XPBD take inside their iterations) or
    "projection" (a position projection after the iterations).

A per-particle term (``per_particle = True``) also gives ``ti.func``s on one particle p,
which the integrators' kernels call in loops over their term lists (so that all terms of
a pass share one launch):

  - ``force(p, x, v, t)`` -> vec3, ``potential(p, x, t)`` -> scalar;
  - backward Euler (after ``begin_step``, which stores the lagged quantities):
    ``incremental(p, x, x0, h, t)`` -> (energy, magnitude, gradient) of its part of the
    incremental potential (magnitude: the sum of absolute values, for rounding bounds) and
    ``hessian_block(p, x, x0, h, t)`` -> its 3x3 block of that potential's Hessian.

Springs are a pair term: their per-spring functions live in ``springs.py`` and the
solvers call them for each spring or grid offset. The other potential terms that couple
particles (bending, the membrane, self-contact) give backward Euler ``add_incremental``,
``prepare_blocks``, ``diagonal_block(p)`` and ``add_product`` (their Hessian's couplings
times a vector, for CG); bending and the membrane also ``local_system(p, x, x0, h)`` (a
particle's gradient and Hessian block at x) for VBD's Gauss-Seidel sweeps and
``constant_matrix()`` for projective dynamics' matrix (an object with ``set_step(h)``,
a per-particle scalar ``diagonal`` and ``add_product``).

A term whose scene data is optional (wind, attraction, self-collision, pressure) names its
``Feature`` (below) as ``feature``: the one description of that data from the scene's
method to the model's fields and the checkpoint.
"""
import numpy as np
import taichi as ti

from ..errors import SceneError
from ..runtime import serial


class Feature:
    """Optional scene data that one module owns, described once.

    ``tcloth.features`` gives ``Scene`` a method named ``method`` for each registered
    feature: it calls ``set`` (validation; its docstring is the method's) and keeps the
    result as ``scene.<name>`` (None until set). ``Model`` keeps ``build(model, value)`` as
    ``model.<name>`` (making the feature's Taichi fields; None for nothing to simulate) and
    ``Model.refresh`` keeps ``refresh(model, value)`` for a ``live`` feature (the
    simulator's live setters change the scene's value, then refresh). A checkpoint stores
    ``saved(value)``, keyword arguments of the scene method that rebuild the value (NumPy
    arrays stored as arrays), and loads it by calling the method with them. ``floor``
    bounds the feature's potential energy from below for the energy budget (``budget.py``).
    """
    name = None
    method = None
    live = False

    def set(self, scene, *args, **kwargs):
        raise NotImplementedError

    def saved(self, value):
        return dict(value)

    def build(self, model, value):
        return value

    def refresh(self, model, value):
        return value

    def floor(self, value, scene):
        """The least potential energy (J) the feature can have: 0 (none below zero), or
        None where it has no lower bound."""
        return 0.0


class Term:
    """Defaults for the interface above."""
    name = None
    feature = None
    implicit = "lagged"
    projective = "lagged"
    per_particle = False
    in_kernel = True

    @staticmethod
    def present(model):
        return True

    def prepare(self, t):
        """Nothing to do before a force evaluation."""

    def batch_obstacle(self):
        return None

    def energy(self, x, t, out):
        return None

    def stored(self, x, t, out):
        """(potential energy or None, largest strain or None) at x: see the module."""
        return self.energy(x, t, out), None

    def begin_step(self, x0, t0):
        """Lagged quantities of backward Euler's step from positions x0 at time t0."""

    def begin_solve(self, x0, v0, h, t0):
        """What an iterative solve of a step of h from (x0, v0) at time t0 fixes at its
        start (the colliders' contact planes)."""


@ti.kernel
def particle_energy(term: ti.template(), x: ti.template(), t: float,
                    out: ti.template()) -> ti.f64:
    """The sum over particles of a per-particle term's potential, accumulated in ``out``'s
    type (f64 where the backend has it)."""
    out[0] = 0
    ti.loop_config(serialize=ti.static(serial(x)))
    for p in range(x.shape[0]):
        out[0] += ti.cast(term.potential(p, x, t), out.dtype)
    return ti.cast(out[0], ti.f64)


def cloth_selection(scene, cloths, rest_positions):
    """(ids, rest) for a per-cloth feature's ``set``: the indices ``cloths`` into
    ``scene.cloths`` (None: every cloth) and the (N,3) rest positions of all particles
    (None: the scene's positions now), checked."""
    count = len(scene.cloths)
    ids = list(range(count)) if cloths is None else [int(c) for c in np.ravel(cloths)]
    if not ids or len(set(ids)) != len(ids) or min(ids) < 0 or max(ids) >= count:
        raise SceneError(f"cloths must be distinct indices into the scene's {count} cloths "
                         f"(got {cloths!r})")
    rest = scene.positions if rest_positions is None else \
        np.asarray(rest_positions, dtype=np.float64)
    if rest.shape != (scene.num_particles, 3) or not np.all(np.isfinite(rest)):
        raise SceneError(f"rest_positions must be finite ({scene.num_particles}, 3) "
                         f"positions (got shape {np.shape(rest_positions)})")
    return ids, rest.copy()


def incidence(ids, n):
    """Each particle's elements, for elements of k particles ids (E,k), as Taichi fields:
    (start (n+1,), entries): particle p's (element, slot) pairs are entries[start[p]:
    start[p+1]], in element order (a gather per particle needs no atomics)."""
    vertex = np.asarray(ids, dtype=np.int64).ravel()
    k = np.shape(ids)[1] if np.ndim(ids) == 2 else 1
    start = ti.field(ti.i32, shape=n + 1)
    start.from_numpy(np.concatenate([[0], np.cumsum(np.bincount(vertex, minlength=n))])
                     .astype(np.int32))
    order = np.argsort(vertex, kind="stable")
    entries = ti.Vector.field(2, ti.i32, shape=max(len(order), 1))
    if len(order):
        entries.from_numpy(np.stack([order // k, order % k], 1).astype(np.int32))
    return start, entries
