"""Extended position-based dynamics (Macklin, Mueller & Chentanez 2016, "XPBD"; with
substeps, Macklin et al. 2019, "Small Steps in Physics Simulation").

The springs are compliant distance constraints C_s = |x_i - x_j| - l0 with compliance
1/k_s and damping k_d: the same springs, not new physics. Hinge bending
(``terms/bending.py``, energy |s|^2 / 2 with s = sum_i c_i x_i linear) is the vector
constraint s = 0 with compliance 1, and a membrane triangle (``terms/membrane.py``) the
three constraints of its stretch and shear conditions, compliances 1 / (A k_c) and
damping beta k_c; hinges and triangles are coloured like the springs (``spring_pass``
takes all three). A pressure chamber (``terms/pressure.py``) is one constraint on all its
particles: every pass ends with a Newton step on its multiplier, the pressure applied,
towards p(V) at the current volume (compliance 1 / (U''(V) h^2), recomputed at each),
moving the particles along dV/dx at the substep's start. A step of h (dt / substeps):

  1. the other forces (gravity, drag, wind, attraction, the grab spring) at the start
     move every velocity, v += h f / m, and x_prev = x, x += h v (pinned particles move
     with their velocity);
  2. ``iterations`` Gauss-Seidel passes over the springs, each colour of springs (no two
     of one colour share a particle) in parallel: with alpha = 1 / (k_s h^2) and
     gamma = k_d / (k_s h),
         dlambda = (-C - alpha lambda - gamma grad C . (x - x_prev))
                   / ((1 + gamma)(w_i + w_j) + alpha),
     x_i += w_i dlambda n, x_j -= w_j dlambda n, lambda += dlambda (n the unit x_ij,
     w the inverse masses, lambda starting at 0 each step);
     After each pass every particle inside a collider's offset surface (its plane of the
     substep's start, ``terms.Colliders.begin_solve``) is put back on it (a hard
     contact constraint, ``push_out``): the iterations see the colliders, so a cloth that
     lands on one is held by it through its springs within the step, not only where its
     particles touch. With self-collision every pass then keeps the contact stage's
     pairs on their sides of their separating planes at the step's start
     (``ContactStage.search_solve``: the candidates of the step's predicted motion,
     searched again where an iterate leaves it; ``ContactStage.keep_apart``, a parallel Jacobi
     pass): the planes are inequality
     constraints of the Gauss-Seidel iterations, and the guard after the step finds
     little left to correct;
  3. v = (x - x_prev) / h; against the colliders it touches, a particle's approaching
     normal velocity is removed and its tangential velocity cut by mu times the normal
     velocity its pushes gave it (Coulomb, ``terms.Colliders.coulomb``); then the
     self-contact projection, as in projective dynamics.

Where the step ends below a mesh collider's planes (the contact stage's for the step's
motion, ``contact/hold.py``), the last substep's iterations run again with each pass
ending on those half-spaces (inequality constraints), and its velocities are taken again.

With many iterations a step solves alpha lambda = -C(x) and M (x - x_pred) = grad C^T
lambda (up to the term XPBD drops, Macklin 2016 eq. 11): backward Euler's step of the
springs with the other forces explicit (tested against the backward Euler step).
"""
import taichi as ti

from .. import runtime
from .. import terms as term_modules
from ..errors import SceneError
from ..terms.forces import Forces
from ..runtime import serial
from ..terms.colliders import Colliders
from .base import Integrator, check_substeps, substep_count, substeps_in_kernel
from .linalg import extrapolate_into


@ti.data_oriented
class XPBD(Integrator):
    """XPBD with substeps. Options (defaults):

    iterations (10): Gauss-Seidel passes over the springs a substep.
    substeps ("auto"): substeps a step (Small Steps: many substeps of one iteration each
        are more accurate than one substep of many iterations, at the same cost); "auto"
        (``base.substep_count``) takes enough that the iterations outrun a stress wave: at
        one substep a stiff cloth or one landing on a capsule is left stretched far past
        what the scene can explain (docs/realtime.md, "The frame-rate solvers' substeps").

    ``colours`` is the springs' colour count.
    """
    name = "xpbd"
    batched = True
    checked_steps = True
    defaults = {"iterations": 10, "substeps": "auto"}
    live_options = frozenset({"iterations", "substeps"})

    def __init__(self, model, contact=None, **options):
        super().__init__(model, contact, **options)
        self.scene = model.scene
        self._configure()
        n, real = model.particle_count, runtime.real()
        self.mass = model.mass
        # the terms with constraints (springs, hinges, triangles, pressure chambers), in
        # TERMS order, and the other forces at each substep's start
        self.constraints = term_modules.build(model, lambda cls: cls.has("constraints"),
                                              contact, constraints=True)
        springs = term_modules.find(self.constraints, term_modules.Springs)
        self.colours = springs.colours if springs is not None else 0
        self.external = Forces(model, lambda cls: cls.projective in ("force", "lagged")
                               and not cls.has("constraints"), contact)
        self.projections = term_modules.build(model, lambda cls: cls.projective == "projection",
                                              contact)
        self.colliders = Colliders(model) if Colliders.present(model) else None
        self.has_colliders = self.colliders is not None
        self.x_prev, self.f, self.dx = (ti.Vector.field(3, real, shape=n) for _ in range(3))
        self.hits = ti.field(ti.i32, shape=n)
        # self-collision: the stage's pairs kept on their planes
        self.keeps_planes = model.self_collision is not None
        self.x_start = ti.Vector.field(3, real, shape=n) if self.keeps_planes else None
        self.pushed = ti.field(real, shape=n)   # how far the colliders pushed, this substep
        # mesh colliders: their planes as constraints after the substeps (``hold.py``)
        self.hold = contact.hold if contact is not None else None
        self.holds = self.hold is not None
        self.constrained = bool(self.constraints)
        self.iterated = self.constrained or self.has_colliders
        self.stats = {}

    def _configure(self):
        """Check the options; the explicit limit for substeps="auto"."""
        value = self.options["iterations"]
        if not (isinstance(value, int) and value >= 1):
            raise SceneError(f"xpbd's iterations must be an int >= 1 (got {value!r})")
        self._explicit_limit = check_substeps("xpbd", self.options["substeps"], self.scene)

    def simulate(self, model, state_in, state_out, dt):
        opt = self.options
        count = substep_count(opt["substeps"], dt, opt["iterations"], self._explicit_limit)
        self.stats = {"substeps": count}
        h = dt / count
        x, v = state_out.x, state_out.v
        self._copy(state_in.x, state_in.v, x, v)
        t = state_in.t
        if self.keeps_planes:
            self.x_start.copy_from(state_in.x)
        for sub in range(count):
            self.external.compute(x, v, t, self.f)
            if self.has_colliders:
                self.colliders.begin_solve(x, v, h, t)
            self._predict(x, v, h)
            if self.iterated:
                if self.keeps_planes and sub == 0:
                    # the step's predicted end: count times the first substep's move
                    extrapolate_into(self.dx, self.x_start, float(count), x)
                    self.contact.search_solve(self.x_start, self.dx, keep_surface=True)
                self._solve(x, h, opt["iterations"])
            self._velocities(x, v, 1.0 / h)
            t += h
            for term in self.projections:
                term.project(x, v, t)
        if self.holds and self.contact.begin_hold(state_in.x, x, state_in.t, dt):
            # the mesh colliders' planes the step ends below, as inequality constraints
            # of the last substep's iterations, run again (``contact/hold.py``)
            for _ in range(opt["iterations"]):
                self._iterate(x, h)
                self._hold_pass(x)
            self.contact.end_hold()
            self._velocities(x, v, 1.0 / h)
            for term in self.projections:
                term.project(x, v, t)
        state_out.t = state_in.t + dt

    @ti.kernel
    def _hold_pass(self, x: ti.template()):
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            self.hold.project(p, x)

    def _solve(self, x, h, iterations):
        """The substep's iterations from the prediction x; with self-collision each pass
        ends keeping the contact stage's pairs on their sides of their planes at the
        step's start (``ContactStage.search_solve`` once a step, for the first substep's
        prediction carried over the step; ``ContactStage.keep_apart``). Every state of the step
        then keeps every pair on its side of one plane, and so do the straight paths
        between them."""
        self._zero_multipliers()
        for _ in range(iterations):
            self._iterate(x, h)
            if self.keeps_planes:
                self.contact.keep_apart(self.x_start, x, self.dx, self.hits)

    def batch_obstacle(self):
        """None where a step can run inside a batch of substeps (``batch.py``): not with
        projections, which run from Python."""
        if self.projections:
            return ("xpbd projects " + " and ".join(t.name or type(t).__name__
                                                    for t in self.projections)
                    + " between its launches")
        for term in self.constraints:
            if term.batch_obstacle() is not None:
                return term.batch_obstacle()
        return self.external.batch_obstacle()

    @ti.func
    def advance(self, a, b, t, dt, fresh):
        """``simulate`` of State a in place, as a ``ti.func`` for the batches (where
        ``batch_obstacle`` is None: no projections); the same functions, in the same
        order. Its iteration count (and substep count, but for "auto") is compiled in:
        ``set_integrator`` changes them."""
        count = substeps_in_kernel(self.options["substeps"], dt, self.options["iterations"],
                                   self._explicit_limit or 0.0)
        # h and 1 / h in float64 first, then rounded, as simulate's Python floats are
        h64 = dt / count
        h = ti.cast(h64, float)
        for sub in range(count):
            t0 = ti.cast(t + sub * h64, float)
            self.external.accumulate(a.x, a.v, t0, self.f)
            if ti.static(self.has_colliders):
                self.colliders.set_planes(a.x, a.v, h, t0)
            self.predict(a.x, a.v, h)
            if ti.static(self.iterated):
                self.zero_multipliers()
                for _ in range(self.options["iterations"]):
                    self.pass_in_order(a.x, h)
                    self.push_out(a.x)
            self.velocities(a.x, a.v, ti.cast(1.0 / h64, float))

    @ti.kernel
    def _copy(self, x_in: ti.template(), v_in: ti.template(), x: ti.template(),
              v: ti.template()):
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            x[p], v[p] = x_in[p], v_in[p]

    @ti.kernel
    def _predict(self, x: ti.template(), v: ti.template(), h: float):
        self.predict(x, v, h)

    @ti.func
    def predict(self, x, v, h):
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            if self.inv_mass[p] > 0.0:
                v[p] += h * self.inv_mass[p] * self.f[p]
            self.x_prev[p] = x[p]
            x[p] += h * v[p]

    @ti.kernel
    def _iterate(self, x: ti.template(), h: float):
        self.spring_pass(x, h)
        self.push_out(x)

    @ti.func
    def push_out(self, x):
        """Every particle inside a collider's offset surface (its planes of the substep's
        start, ``Colliders.begin_solve``) back on it, the distance added to ``pushed``."""
        if ti.static(self.has_colliders):
            ti.loop_config(serialize=ti.static(serial(x)))
            for p in range(x.shape[0]):
                self.pushed[p] += self.colliders.push_out(p, x)

    @ti.kernel
    def _zero_multipliers(self):
        self.zero_multipliers()

    @ti.func
    def zero_multipliers(self):
        """No multipliers and no collider push yet: a substep starts without them."""
        if ti.static(self.has_colliders):
            ti.loop_config(serialize=ti.static(serial(self.pushed)))
            for p in range(self.pushed.shape[0]):
                self.pushed[p] = 0
        for term in ti.static(self.constraints):
            term.zero_multipliers(self.x_prev)

    @ti.func
    def spring_pass(self, x, h):
        """One Gauss-Seidel pass over every term's constraints in turn (springs, hinges,
        triangles, pressure chambers), each term's colour after colour (module
        docstring; one launch)."""
        for term in ti.static(self.constraints):
            term.constraint_pass(x, self.x_prev, h)

    @ti.func
    def pass_in_order(self, x, h):
        """``spring_pass`` inside a batch, where it runs on one thread: the same
        projections in the same order, each kind's code inlined once instead of once per
        colour."""
        for term in ti.static(self.constraints):
            term.constraint_pass_in_order(x, self.x_prev, h)

    @ti.kernel
    def _velocities(self, x: ti.template(), v: ti.template(), inv_h: float):
        self.velocities(x, v, inv_h)

    @ti.func
    def velocities(self, x, v, inv_h):
        """v = (x - x_prev) / h, then Coulomb friction against the colliders touched (the
        pushes' distance over h is the normal velocity change)."""
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            v[p] = (x[p] - self.x_prev[p]) * inv_h
            if ti.static(self.has_colliders):
                self.colliders.plane_coulomb(p, x, v, self.pushed[p] * inv_h)
