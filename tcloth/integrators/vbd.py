"""Vertex Block Descent (Chen, Liu, Yang & Yuksel, ACM TOG 43(4), 2024).

Backward Euler's step minimises the incremental potential E(x) (``potential.py``). VBD
minimises it by block coordinate descent: one vertex at a time, all others held, E as a
function of that vertex's position alone is its inertia m/(2h^2) |x_i - x_hat_i|^2 plus the
terms touching it, and one Newton step on it,

    x_i <- x_i - H_i^-1 g_i,

with g_i its gradient and H_i its 3 x 3 Hessian block (the springs' blocks projected to
positive semi-definite, as backward Euler's preconditioner has them), lowers E when H_i is
positive definite. Vertices that share no spring do not change each other's block, so they
are updated together: the particle graph (an edge per spring, every family) is coloured
greedily once per model, and an iteration is one parallel pass per colour. Since E is
backward Euler's own potential, VBD's iterates converge to backward Euler's step (tested),
and damping, friction, colliders and the grab spring enter as they do there, but for
friction's block: sliding, its potential is a cone with no curvature along the sliding,
where a vertex's Newton step with the exact block overshoots the stop (the fold's landing
row shot off at 15 m/s), so VBD takes its majorant's (``colliders.add_dissipation``).

Hinge bending (``terms/bending.py``) and the triangle membrane (``terms/membrane.py``) are
Gauss-Seidel like the springs: a vertex's gradient and block are summed over its hinges and
triangles at the current positions, and vertices sharing a hinge or a triangle get
different colours. Self-contact couples vertices through the contact list, which changes
every step: each vertex's rows are evaluated afresh in its update too
(``SelfContact.vertex_system``, from a per-vertex index made at the step's start), but they
are not in the colouring, so two vertices of one colour may share a row. The penalty's
stiffness switches on at the thickness, where a Newton step from outside overshoots: a step
that can bring a row into contact is searched along (``vbd_local.py``), so that VBD
converges to backward Euler's step in contact too (tested). Each iteration ends keeping the
contact stage's pairs on their sides of their separating planes at the whole step's start,
in every substep (``ContactStage.search_solve`` once a step, for the first substep's guess
carried over the step, searched again where an iterate leaves it, a plane it crosses chosen
again for its motion; ``ContactStage.keep_apart``): the guard checks the step's motion against
these planes, and substeps that kept only their own left it corrections that stretch the
cloth (``docs/realtime.md``). Chebyshev's mix is skipped in an iteration after one whose
planes moved a vertex (extrapolating a plane's move tore the fold at its first step); the
contact stage's guard (``contact/guard.py``) keeps the step free of crossings as for every
integrator. Pressure couples every vertex of a chamber (``terms/pressure.py``): it is a
Jacobi term too, with diagonal blocks that bound its rank-one part so that the vertices'
simultaneous moves do not overshoot the chamber's volume. With ``bounds=True`` every move
is kept inside its vertex's conservative displacement bound (``contact/bounds.py``, as
Offset Geometric Contact does), detected at the step's start and again after an iteration
that clamped a move, so the iterations never take cloth through cloth, at the price of
capping how fast cloth near other cloth can move.

Where a scene has neither colliders nor self-contact, ``step(n)`` runs its n steps in one
kernel launch (``advance``, ``batch.py``), the same functions as the launches from Python
and so the same numbers.

Chebyshev acceleration (the paper's Section 3.7; Wang 2015) mixes each iterate with the one
two iterations back, x^(n) = w_n (x^(n) - x^(n-2)) + x^(n-2), with w_1 = 1, w_2 = 2 / (2 -
rho^2), w_n = 4 / (4 - rho^2 w_(n-1)), rho the estimated spectral radius of the plain
iteration (0: off), for the particles no collider can reach in the step: a collider's
penalty switches on and off between iterations, and extrapolating through it made a cloth
lying on a frictionless floor creep across it (``accelerate``).
"""
import numpy as np
import taichi as ti

from ..errors import SceneError
from ..geometry.graph import colour_graph, colour_order, csr_layout
from ..runtime import serial
from ..terms import springs as spring_term
from ..terms.springs import Springs
from .base import (ForceCache, Integrator, check_substeps, substep_count,
                   substeps_in_kernel)
from .linalg import copy, copy_into, extrapolate_into
from .potential import IncrementalPotential
from .vbd_local import VertexLocal

GUESSES = ("start", "inertia", "gravity", "adaptive")
GRAVITY_GUESS = GUESSES.index("gravity")


def chebyshev(rho, iterations):
    """(iterations + 1,) f64: Chebyshev's weight w_n for iteration n = 1..iterations (w_1 = 1,
    w_2 = 2 / (2 - rho^2), w_n = 4 / (4 - rho^2 w_(n-1))); entry 0 unused."""
    omega = np.ones(iterations + 1)
    for n in range(2, iterations + 1):
        omega[n] = 2.0 / (2.0 - rho * rho) if n == 2 else 4.0 / (4.0 - rho * rho * omega[n - 1])
    return omega


@ti.data_oriented
class VBD(VertexLocal, ForceCache, Integrator):
    """Vertex Block Descent on backward Euler's incremental potential. Options (defaults):

    iterations (10): colour sweeps a step (VBD does not test convergence: the count is
        its accuracy; docs/benchmarks.md measures the error each reaches).
    rho (0.9): Chebyshev acceleration's spectral radius estimate, in [0, 1); 0 is off.
        The particles a collider can reach in the step are not accelerated
        (``accelerate``).
    initial_guess ("adaptive"): where the iterations start: "start" (x_t), "inertia"
        (x_t + h v_t), "gravity" (x_t + h v_t + h^2 g), or "adaptive" (the paper's:
        gravity scaled by how much of it the last step's acceleration had, in [0, 1]).
    substeps ("auto"): steps of dt / substeps a step; "auto" (``base.substep_count``)
        takes enough that the iterations outrun a stress wave, which a Gauss-Seidel sweep
        carries one particle further: at one substep a cloth landing on a capsule or
        hanging on stiff springs is left stretched far past what its fall can explain
        (docs/realtime.md, "The frame-rate solvers' substeps").
    bounds (False): with self-collision, keep every move inside Offset Geometric Contact's
        conservative displacement bounds (module docstring). The solve then never takes
        cloth through cloth and the contact guard has almost nothing to do, but the
        bounds, set by the proximity list's reach, cap how far a particle moves a step,
        which holds falling cloth back (docs/realtime.md, "Why the bounds are off by
        default"). Off (the default), the iterations keep the stage's pairs on their
        separating planes instead, which caps only motion toward a neighbour.

    A step leaves its net force m (v - v0) / h in the state's force accumulator, for the
    adaptive guess of the next (like Verlet's cached forces, dropped when the state is
    changed from outside, and kept by checkpoints). ``colours`` (the greedy colouring's
    count) and, after each step, ``stats``
    (iterations; potential: E at the initial guess and at the end where
    ``track_potential`` is set, which costs two evaluations of E a step) describe the
    solve.
    """
    name = "vbd"
    batched = True
    checked_steps = True
    defaults = {"iterations": 10, "rho": 0.9, "initial_guess": "adaptive", "bounds": False,
                "substeps": "auto"}
    live_options = frozenset({"iterations", "rho", "initial_guess", "substeps"})

    def __init__(self, model, contact=None, **options):
        super().__init__(model, contact, **options)
        opt = self.options
        n, real = model.particle_count, model.mass.dtype
        self.model = model
        self._configure()
        self.potential = IncrementalPotential(model, contact, jacobi=True, per_vertex=True,
                                              friction_majorant=True)
        self.springs = self.potential.springs
        self.has_springs = self.springs is not None
        self.adj_start, self.adj = (self.springs or Springs(model)).adjacency()
        if self.has_springs:
            self.pairs, self.rest = self.springs.pairs, self.springs.rest
            self.ks, self.kd = self.springs.ks, self.springs.kd
        # bending and the membrane are Gauss-Seidel like the springs; pressure is Jacobi,
        # held through an iteration (its term option ``jacobi``: bounding blocks)
        self.local_terms = tuple(t for t in self.potential.pair_terms
                                 if t.has("local_system"))
        # self-contact: each particle's rows evaluated afresh in its update (not in the
        # colouring: they change every step)
        self.vertex_terms = tuple(t for t in self.potential.pair_terms
                                  if t.has("vertex_system"))
        self.pair_terms = tuple(t for t in self.potential.pair_terms
                                if t not in self.local_terms + self.vertex_terms)
        self.mass, self.params = model.mass, model.params
        self.order, self.colour_start = self._colouring(n)
        self.colours = len(self.colour_start) - 1
        self.prev, self.prev2, self.contact_grad, self.v_start, self.dx = (
            ti.Vector.field(3, real, shape=n) for _ in range(5))
        self.hits, self.deferred = (ti.field(ti.i32, shape=n) for _ in range(2))
        # mesh colliders: their planes as a penalty after the sweeps (``hold.py``)
        self.holds = self.potential.hold is not None
        # the colliders' planes of each step (``accelerate`` skips the particles they reach)
        self.colliders = next((t for t in self.potential.particle_terms
                               if t.has("contact_planes")), None)
        self.has_colliders = self.colliders is not None
        self.bounds = (contact.displacement_bounds()
                       if opt["bounds"] and contact is not None else None)
        self.bounded = self.bounds is not None
        # with self-collision and no bounds, the stage's pairs kept on their planes
        self.keeps_planes = (not self.bounded and contact is not None
                             and contact.broad is not None)
        self.x_start = ti.Vector.field(3, real, shape=n) if self.keeps_planes else None
        self.track_potential = False
        self.stats = {}
        if self.has_springs:
            self.springs.implicit_fields()

    def _configure(self):
        """Check the live options; the guess's index, the Chebyshev weights (a batch's
        table) and the explicit limit for substeps="auto"."""
        opt = self.options
        if not (isinstance(opt["iterations"], int) and opt["iterations"] >= 1):
            raise SceneError(f"vbd's iterations must be an int >= 1 (got {opt['iterations']!r})")
        if not 0.0 <= float(opt["rho"]) < 1.0:
            raise SceneError(f"vbd's rho must be in [0, 1) (got {opt['rho']!r})")
        if opt["initial_guess"] not in GUESSES:
            raise SceneError(f"vbd's initial_guess must be one of {GUESSES} "
                             f"(got {opt['initial_guess']!r})")
        self._explicit_limit = check_substeps("vbd", opt["substeps"], self.model.scene)
        self.guess_kind = GUESSES.index(opt["initial_guess"])
        self.omegas = ti.field(ti.f64, shape=opt["iterations"] + 1)
        self.omegas.from_numpy(chebyshev(float(opt["rho"]), opt["iterations"]))

    def _colouring(self, n):
        """(order, colour_start): the particles sorted by colour as an i32 field, and the
        Python list of each colour's first entry in it (and the end). Particles joined by
        a spring or sharing a hinge or a triangle get different colours."""
        start = self.adj_start.to_numpy().astype(np.int64)
        others = self.adj.to_numpy()[:, 1].astype(np.int64) if start[-1] else np.zeros(0, int)
        ends = np.repeat(np.arange(n), np.diff(start))
        pairs = [np.stack([ends, others], 1)] + [t.coupled_pairs() for t in self.local_terms]
        pairs = np.unique(np.concatenate(pairs), axis=0)
        pairs = np.concatenate([pairs, pairs[:, ::-1]])
        start, order = csr_layout(pairs[:, 0], n)
        return colour_order(colour_graph(start, pairs[order, 1], n))

    def simulate(self, model, state_in, state_out, dt):
        count = substep_count(self.options["substeps"], dt, self.options["iterations"],
                              self._explicit_limit)
        source = state_in
        for sub in range(count):
            self._substep(model, source, state_out, dt / count, count if sub == 0 else 0)
            source = state_out
        self.stats["substeps"] = count

    def _substep(self, model, state_in, state_out, dt, predict=0):
        """One step of dt from state_in to state_out (which may be the same State: the
        step's start is then read from the potential's copy x0); ``predict``: the step's
        substeps, where this is its first (the step's planes are searched)."""
        copy_into(self.v_start, state_in.v)
        h, t1 = dt, state_in.t + dt
        opt = self.options
        x, e = state_out.x, self.potential
        e.begin(state_in.x, state_in.v, h, state_in.t, x)
        x0 = e.x0
        guess = opt["initial_guess"]
        if guess == "adaptive" and self._cached is not state_in:
            guess = "gravity"
        self._guess(x, state_in.f, h, GUESSES.index(guess))
        if self.bounds is not None:
            self.contact.detect_bounds(self.bounds, x0)
            self._clamp(x)
        if self.keeps_planes and predict:      # the step's start and predicted end
            self.x_start.copy_from(x0)
            extrapolate_into(self.dx, self.x_start, float(predict), x)
            self.contact.search_solve(self.x_start, self.dx)
        if self.keeps_planes:      # the planes chosen again for the first iterate
            self.contact.follow_solve(self.x_start, x, True)
        pushed = False
        energies = [e.evaluate(x, h, t1, False)[0]] if self.track_potential else []
        rho = float(opt["rho"])
        omegas = chebyshev(rho, opt["iterations"])
        for it in range(1, opt["iterations"] + 1):
            if rho > 0.0:
                self._remember(x)
            self._contacts(x, h)
            self._sweep(x, h, t1)
            if rho > 0.0 and it > 1 and not pushed:
                self._accelerate(x, omegas[it])
            if self.keeps_planes:
                pushed = self.contact.keep_apart(self.x_start, x, self.dx, self.hits, True) > 0
            if self.bounds is not None and self.bounds.any_clamped() and it < opt["iterations"]:
                if self.contact.detect_bounds(self.bounds, x):
                    for term in self.pair_terms + self.vertex_terms:  # the rows changed
                        term.begin_step(x0, state_in.t)
        if self.holds and self.contact.begin_hold(x0, x, state_in.t, h):
            # the mesh colliders' planes the step ends below, as a penalty in E
            # (``contact/hold.py``): the sweeps again
            for _ in range(opt["iterations"]):
                self._contacts(x, h)
                self._sweep(x, h, t1)
            self.contact.end_hold()
        if self.track_potential:
            energies.append(e.evaluate(x, h, t1, False)[0])
        self._finish(x, self.v_start, 1.0 / h, state_out.v, state_out.f)
        self._cached = state_out
        state_out.t = t1
        self.stats = {"iterations": opt["iterations"], "potential": energies}

    def batch_obstacle(self):
        """None where a step can run inside a batch of substeps (``batch.py``): not with
        self-contact (gathered from Python every iteration) or colliders (their contacts
        at the step's start are stored by a launch)."""
        if self.pair_terms or self.vertex_terms:
            return ("vbd gathers its Jacobi terms (pressure) and self-contact's rows from "
                    "Python every iteration or step")
        if self.has_colliders:
            return "vbd stores the colliders' contacts at each step's start with a launch"
        for term in self.potential.terms:
            if term.batch_obstacle() is not None:
                return term.batch_obstacle()
        return self.potential.lagged.batch_obstacle()

    @ti.func
    def advance(self, a, b, t, dt, fresh):
        """``simulate`` of State a in place (b.v holds v0, b.x the unused x_hat copy), as a
        ``ti.func`` for the batches (where ``batch_obstacle`` is None): the same
        functions in the same order. Its iteration count (and substep count, but for
        "auto") is compiled in: ``set_integrator`` changes them."""
        count = substeps_in_kernel(self.options["substeps"], dt, self.options["iterations"],
                                   self._explicit_limit or 0.0)
        h64 = dt / count
        h = ti.cast(h64, float)
        for sub in range(count):
            copy(b.v, a.v)
            self.potential.begin_particles(a.x, a.v, h, b.x)
            if ti.static(self.has_springs):
                self.springs.begin_directions(self.potential.x0)
            t0 = ti.cast(t + sub * h64, float)
            if ti.static(self.potential.has_lagged):
                self.potential.lagged.accumulate(a.x, a.v, t0, self.potential.f_lag)
            kind = self.guess_kind
            if ti.static(self.options["initial_guess"] == "adaptive"):
                if fresh and sub == 0:
                    kind = GRAVITY_GUESS
            self.guess(a.x, a.f, h, kind)
            t1 = ti.cast(t + (sub + 1) * h64, float)
            for it in range(1, self.options["iterations"] + 1):
                if ti.static(self.options["rho"] > 0.0):
                    self.remember(a.x)
                self.sweep_in_order(a.x, h, t1)
                if ti.static(self.options["rho"] > 0.0):
                    if it > 1:
                        self.accelerate(a.x, ti.cast(self.omegas[it], float))
            self.finish(a.x, b.v, ti.cast(1.0 / h64, float), a.v, a.f)

    def _contacts(self, x, h):
        """The pair terms' (self-contact's) gradient and diagonal blocks at x, held through
        the iteration's colour passes."""
        if not self.pair_terms:
            return
        self.contact_grad.fill(0)
        for term in self.pair_terms:
            # the energy sums go to the potential's accumulator, which evaluate() zeroes
            term.add_incremental(x, self.potential.x0, h, True, self.potential.acc,
                                 self.contact_grad)
            term.prepare_blocks(x, self.potential.x0, h)

    @ti.kernel
    def _guess(self, x: ti.template(), f: ti.template(), h: float, kind: ti.i32):
        self.guess(x, f, h, kind)

    @ti.func
    def guess(self, x, f, h, kind):
        """x at the initial guess (GUESSES[kind]; "adaptive" reads the last step's m a in
        f); pinned particles at x_hat = x0 + h v0 (they move with their velocity)."""
        g = ti.Vector([self.params[0], self.params[1], self.params[2]])
        g_norm = g.norm()
        ti.loop_config(serialize=ti.static(serial(self.mass)))
        for p in range(self.mass.shape[0]):
            y = self.potential.x_hat[p]
            if self.potential.inv_mass[p] > 0.0:
                if kind == 0:
                    y = self.potential.x0[p]
                elif kind == 2:
                    y += h * h * g
                elif kind == 3 and g_norm > 0.0:
                    # the last step's acceleration along gravity, as a fraction of it
                    along = (f[p] * self.potential.inv_mass[p]).dot(g) / (g_norm * g_norm)
                    y += h * h * ti.math.clamp(along, 0.0, 1.0) * g
            x[p] = y

    @ti.func
    def _local(self, p, x, h, t):
        """(g_i, H_i, clearance): vertex p's gradient of E and its 3 x 3 Hessian block at
        x, the springs' projected (the Jacobi terms' from the iteration's start), and how
        far it may move before a self-contact row of its own comes into contact."""
        g = self.mass[p] / (h * h) * (x[p] - self.potential.x_hat[p])
        clearance = 1e30
        for term in ti.static(self.potential.particle_terms):
            g += term.incremental(p, x, self.potential.x0, h, t)[2]
        if ti.static(self.potential.has_lagged):
            g -= self.potential.f_lag[p]
        if ti.static(bool(self.pair_terms)):
            g += self.contact_grad[p]
        block = self.potential.inertial_block(p, x, h, t)
        for term in ti.static(self.pair_terms):
            block += term.diagonal_block(p)
        for term in ti.static(self.local_terms):
            g_t, block_t = term.local_system(p, x, self.potential.x0, h)
            g += g_t
            block += block_t
        for term in ti.static(self.vertex_terms):
            g_t, block_t, clear_t = term.vertex_system(p, x, self.potential.x0, h)
            g += g_t
            block += block_t
            clearance = ti.min(clearance, clear_t)
        if ti.static(self.has_springs):
            d0 = ti.static(self.springs.d0)
            for a in range(self.adj_start[p], self.adj_start[p + 1]):
                s, q = self.adj[a][0], self.adj[a][1]
                sign = 1.0 if self.pairs[s][0] == p else -1.0
                # the second of each pair (one name for the first would be a scalar's
                # and a matrix's: Taichi stores a matrix into a scalar's slot)
                g += spring_term.incremental(x[p], x[q], self.potential.x0[p], self.potential.x0[q],
                                             sign * d0[s], self.ks[s], self.kd[s], self.rest[s],
                                             h)[1]
                block += spring_term.hessian_blocks(x[p], x[q], self.ks[s], self.kd[s],
                                                    self.rest[s], d0[s], h)[1]
        return g, block, clearance

    def _sweep(self, x, h, t):
        """One iteration: each free vertex's Newton step, a launch per colour (one kernel,
        compiled once: the range is data); then the steps deferred to a line search."""
        layout = self._layout()
        for c in range(self.colours):
            self._colour_kernel(x, h, t, self.colour_start[c], self.colour_start[c + 1],
                                layout)
        if self.vertex_terms:
            self._deferred_kernel(x, h, t, layout)

    def _layout(self):
        """The vertex terms' ``layout``s: a sweep compiles again where one changed."""
        return tuple(term.layout() for term in self.vertex_terms)

    @ti.kernel
    def _colour_kernel(self, x: ti.template(), h: float, t: float, begin: ti.i32,
                       end: ti.i32, layout: ti.template()):
        for k in range(begin, end):
            self._update(self.order[k], x, h, t)

    @ti.kernel
    def _deferred_kernel(self, x: ti.template(), h: float, t: float, layout: ti.template()):
        self.deferred_pass(x, h, t)

    @ti.func
    def sweep_in_order(self, x, h, t):
        """``_sweep`` inside a batch, where it runs on one thread: the vertices one after
        another in colour order (the order is sorted by colour), the same updates in the
        same order as the colour passes."""
        for k in range(ti.static(self.colour_start[-1])):
            self._update(self.order[k], x, h, t)

    @ti.func
    def _update(self, p, x, h, t):
        """Vertex p's Newton step, if it is free; with self-contact, deferred to the
        sweep's line search where it can bring a row into contact (``vbd_local.py``)."""
        if self.potential.inv_mass[p] > 0.0:
            g, block, clearance = self._local(p, x, h, t)
            step = -(block.inverse() @ g)
            defer = False
            if ti.static(bool(self.vertex_terms)):
                defer = step.norm() >= clearance
            if defer:
                self.deferred[p] = 1
            else:
                x[p] = self._bounded(p, x[p] + step)

    @ti.func
    def _bounded(self, p, y):
        """y, or with self-collision y clamped into p's displacement bound."""
        out = y
        if ti.static(self.bounded):
            out = self.bounds.clamp(p, y)
        return out

    @ti.kernel
    def _clamp(self, x: ti.template()):
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            if self.potential.inv_mass[p] > 0.0:
                x[p] = self._bounded(p, x[p])

    @ti.kernel
    def _remember(self, x: ti.template()):
        self.remember(x)

    @ti.func
    def remember(self, x):
        """prev2 <- prev <- x: the iterates one and two iterations back."""
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            self.prev2[p] = self.prev[p]
            self.prev[p] = x[p]

    @ti.kernel
    def _accelerate(self, x: ti.template(), omega: float):
        self.accelerate(x, omega)

    @ti.func
    def accelerate(self, x, omega):
        """Chebyshev's mix, for the free particles that no collider can reach this step.
        A collider's penalty switches on and off between iterations, where the mix's
        extrapolation (which assumes one linear iteration) overshoots: with it, a cloth
        lying on a frictionless floor crept across it (0.018 kg m/s of a 0.3 kg cloth
        after 0.5 s at 1/60, particles at up to 0.38 m/s; ``docs/contact.md``)."""
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            if self.potential.inv_mass[p] > 0.0 and not self._near_collider(p):
                x[p] = self._bounded(p, omega * (x[p] - self.prev2[p]) + self.prev2[p])

    @ti.func
    def _near_collider(self, p):
        near = False
        if ti.static(self.has_colliders):
            near = self.colliders.reaches(p)
        return near

    @ti.kernel
    def _finish(self, x: ti.template(), v0: ti.template(), inv_h: float,
                v_out: ti.template(), f_out: ti.template()):
        self.finish(x, v0, inv_h, v_out, f_out)

    @ti.func
    def finish(self, x, v0, inv_h, v_out, f_out):
        """v = (x - x0) / h, and f = m (v - v0) / h: the step's net force, which the
        adaptive guess of the next step reads (``holds_forces``)."""
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            v_out[p] = (x[p] - self.potential.x0[p]) * inv_h
            f_out[p] = self.mass[p] * (v_out[p] - v0[p]) * inv_h
