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
    ``add_forces(x, v, t, f_out)`` (kernel launches) instead; where it also gives an
    ``accumulate`` for a batch of substeps (``in_batch = True``), that reads its fields as
    they were when the batch compiled, and the batch is compiled again where they were
    made again (self-contact: ``ContactStage.batch_key``);
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
particle's gradient and Hessian block at x) and ``local_energy`` for VBD's Gauss-Seidel
sweeps and ``constant_matrix()`` for projective dynamics' matrix (an object with
``set_step(h)``, a per-particle scalar ``diagonal`` and ``add_product``).

What a term gives beyond the above is declared, not guessed: its class lists its
capabilities in ``provides`` (names of ``CAPABILITIES``, below, each with the methods it
requires), and the solvers ask ``term.has(name)``. Declaring a capability whose methods
are missing, or defining all of a capability's methods without declaring it, is an error
when the class is made. Options that a term compiles into its kernels (``exact``,
``jacobi``) are declared in ``options`` (name -> default) and given when it is built
(``terms.build(model, select, **options)`` passes each term the ones it declares).

A term whose scene data is optional (bending, the membrane, wind, attraction, pressure,
self-collision) names its ``Feature`` (``tcloth.features``) as ``feature``: the one
description of that data from the scene's method to the model's object (``model.<feature
name>``, which the term reads) and the checkpoint.
"""
import taichi as ti

from .. import runtime
from ..geometry.graph import colour_order, colour_springs
from ..runtime import serial


# The capabilities a term may declare (``Term.provides``): name -> the methods it needs.
CAPABILITIES = {
    # backward Euler's couplings between particles (bending, the membrane, pressure,
    # self-contact): their part of the incremental potential and its gradient, the
    # Hessian's diagonal blocks (``prepare_blocks``, then the ti.func ``diagonal_block(p)``)
    # and the couplings' product with a vector, for CG
    "couplings": ("add_incremental", "prepare_blocks", "diagonal_block", "add_product"),
    # VBD's Gauss-Seidel sweeps: particle p's gradient and Hessian block at x (ti.func
    # ``local_system(p, x, x0, h)``) and its energy as a function of x[p] alone, up to a
    # constant (``local_energy(p, x, x0, h)``, for the line search); a coupled term
    # without them is taken Jacobi-style
    "local_system": ("local_system", "local_energy"),
    # VBD's sweeps, for a coupling that changes every step (self-contact): particle p's
    # gradient, Hessian block and clearance (how far it may move before a coupling of its
    # own switches on) at x from its rows evaluated afresh (ti.func ``vertex_system(p, x,
    # x0, h)``), the couplings left out of the colouring; its energy as ``local_energy``'s
    # (``vertex_energy``); and ``layout()``, an int that changes where the fields it reads
    # were made again
    "vertex_system": ("vertex_system", "vertex_energy", "layout"),
    # projective dynamics' matrix: ``constant_matrix()``, a ``ConstantMatrix``
    "constant_matrix": ("constant_matrix",),
    # XPBD's compliant constraints (built with the option ``constraints=True`` where the
    # term declares it): ti.funcs ``zero_multipliers(x_prev)`` (a substep's start, at its
    # positions x_prev), ``constraint_pass(x, x_prev, h)`` (every constraint once, colour
    # after colour, each colour's in parallel) and ``constraint_pass_in_order(x, x_prev,
    # h)`` (the same projections one after another, for a batch's single thread)
    "constraints": ("zero_multipliers", "constraint_pass", "constraint_pass_in_order"),
    # a position and velocity projection after a solve (self-contact's)
    "projection": ("project",),
    # the colliders' contact planes of an iterative solve (``Colliders.begin_solve``)
    "contact_planes": ("begin_solve", "set_planes", "push_out", "plane_force"),
}


class Term:
    """Defaults for the interface above."""
    name = None
    feature = None
    implicit = "lagged"
    projective = "lagged"
    per_particle = False
    in_kernel = True
    in_batch = False
    provides = frozenset()
    options = {}
    # built with the simulator's contact stage (``contact=``; ``terms.build``)
    reads_contact = False
    work = 1            # what a particle's evaluation costs, in simple items (runtime.serial)

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        for capability, methods in CAPABILITIES.items():
            defined = [callable(getattr(cls, m, None)) for m in methods]
            if capability in cls.provides and not all(defined):
                missing = [m for m, d in zip(methods, defined) if not d]
                raise TypeError(f"{cls.__name__} provides {capability!r} without "
                                f"{', '.join(missing)}")
            if capability not in cls.provides and all(defined):
                raise TypeError(f"{cls.__name__} defines {', '.join(methods)} but does not "
                                f"declare {capability!r} in provides")
        unknown = sorted(set(cls.provides) - set(CAPABILITIES))
        if unknown:
            raise TypeError(f"{cls.__name__} provides unknown capabilities {unknown}")

    @classmethod
    def has(cls, capability):
        """Whether the term declares ``capability`` (a name of ``CAPABILITIES``)."""
        if capability not in CAPABILITIES:
            raise ValueError(f"no capability {capability!r} (known: {sorted(CAPABILITIES)})")
        return capability in cls.provides

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


class ColouredConstraints:
    """XPBD's constraints of a term whose elements (springs, hinges, triangles) each give
    one (vector) constraint (the "constraints" capability): ``constraints_begin`` colours
    the elements (no two of a colour share a particle: ``graph.colour_springs``) and makes
    their multipliers; the term gives ``project_constraint(x, x_prev, h, k)``, element
    k's projection (Gauss-Seidel: x moves, its multiplier grows)."""

    def constraints_begin(self, elements, n, width):
        """Colour ``elements`` ((E, k) particle ids, NumPy) on n particles and make their
        multipliers, ``width`` numbers each (1: a scalar field)."""
        real = runtime.real()
        self.width = width
        self.lam = (ti.field(real, shape=max(len(elements), 1)) if width == 1 else
                    ti.Vector.field(width, real, shape=max(len(elements), 1)))
        self.constraint_order, self.colour_start = colour_order(colour_springs(elements, n))
        self.colours = len(self.colour_start) - 1

    @ti.func
    def zero_multipliers(self, x_prev):
        """lambda = 0 for every element: a substep starts without them."""
        ti.loop_config(serialize=True)
        for k in range(self.lam.shape[0]):
            if ti.static(self.width == 1):
                self.lam[k] = 0
            else:
                self.lam[k] = ti.Vector.zero(float, self.width)

    @ti.func
    def constraint_pass(self, x, x_prev, h):
        """Every element's projection once, colour after colour, a colour's elements in
        parallel (the colours' loops unrolled, each a top-level loop)."""
        for c in ti.static(range(self.colours)):
            for k in range(ti.static(self.colour_start[c]), ti.static(self.colour_start[c + 1])):
                self.project_constraint(x, x_prev, h, self.constraint_order[k])

    @ti.func
    def constraint_pass_in_order(self, x, x_prev, h):
        """``constraint_pass`` on one thread (a batch): the same projections in the same
        order, the projection's code inlined once instead of once per colour."""
        for k in range(ti.static(self.colour_start[-1])):
            self.project_constraint(x, x_prev, h, self.constraint_order[k])


class ConstantMatrix:
    """What a term's ``constant_matrix()`` gives projective dynamics: a symmetric positive
    semi-definite stand-in for its Hessian, entering the solver's matrix A whole. It has a
    per-particle scalar ``diagonal`` (a field; its 3 x 3 block is diagonal times I),
    ``set_step(h)`` (before use and whenever the step changes), ``add_product(v, out,
    first)`` (out += its couplings times v; out = when ``first``) and, where it changes
    with each step's start (``varies``), ``update(x0)``."""
    varies = False

    def set_step(self, h):
        """Nothing: the matrix does not depend on the step."""

    def update(self, x0):
        """Nothing: the matrix does not change with the step's start."""


@ti.kernel
def particle_energy(term: ti.template(), x: ti.template(), t: float,
                    out: ti.template()) -> ti.f64:
    """The sum over particles of a per-particle term's potential, accumulated in ``out``'s
    type (f64 where the backend has it)."""
    out[0] = 0
    ti.loop_config(serialize=ti.static(serial(x, term.work)))
    for p in range(x.shape[0]):
        out[0] += ti.cast(term.potential(p, x, t), out.dtype)
    return ti.cast(out[0], ti.f64)


@ti.func
def add_or_set(out: ti.template(), p, value, first: ti.template()):
    """out[p] = value where ``first``, else out[p] += value (``add_product``'s two
    modes)."""
    if ti.static(first):
        out[p] = value
    else:
        out[p] += value


@ti.func
def norm_above(v, floor):
    """|v| where it exceeds ``floor`` (>= 0), else ``floor``: the norm only where its
    derivative exists (at v = 0 Taichi's reverse mode takes 0/0 there, a NaN)."""
    s2 = v.dot(v)
    length = floor
    if s2 > floor * floor:
        length = ti.sqrt(s2)
    return length
