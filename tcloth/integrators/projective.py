"""Projective dynamics for mass-spring systems: the local/global solver of Liu, Bargteil,
O'Brien & Kavan 2013, "Fast Simulation of Mass-Spring Systems".

A backward Euler step minimises 1/(2h^2) |x - y|_M^2 + sum_s k_s/2 |x_i - x_j - d_s|^2
over positions x and spring directions d_s with |d_s| = l0_s, alternating
  local:  d_s = l0_s (x_i - x_j) / |x_i - x_j|            (every spring in parallel)
  global: A x = M/h^2 y + J d,  A = M/h^2 + sum_s k_s A_s A_s^T   (one constant matrix)
with y = x0 + h v0 + h^2 M^-1 f_ext. Subtracting A x_k from both sides, the global step is
x_{k+1} = x_k + A^-1 g(x_k) with g the step's force residual

    g(x) = M/h^2 (y - x) + f(x, (x - x0) / h),

f the springs' forces -k_s (|x_ij| - l0) d (the local step and J d - sum k_s A_s A_s^T x
together are exactly these) and the others: Liu's iteration is a quasi-Newton method
with the constant matrix A in place of the Hessian. That is how it runs here: f is the
ordinary force evaluation at each iterate (gravity, air drag, springs with their axial
damping k_d (v_ij . d) d), wind and attraction enter y at the start of the step as in
the paper, and A carries the constant parts, M/h^2 + c/h + sum_s (k_s + k_d/h)
A_s A_s^T (k_d/h A_s A_s^T bounds the axial damping's Jacobian: d d^T <= I) and the
Hessian of hinge bending (constant: ``terms/bending.py``), whose energy is already
quadratic, as Liu's constraints with projection p = 0 are, and the triangle membrane's
rotation-invariant bound (``terms/membrane.py``), as Liu's springs' A_s A_s^T are. A
pressure chamber's gas is in f too, and its stiffness k g g^T (``terms/pressure.py``;
seven times the springs' against a sea-level balloon's breathing) in A, taken at each
step's start (``update``) and applied in CG's products. The fixed point is the
backward Euler step with axial spring damping, so damped motion is as accurate as
backward Euler's (Liu's paper damps only through the medium).

The global solve, A is constant per scene and dt:
  - a scene that is one cloth grid and nothing else: one geometric multigrid V-cycle per
    iteration (``multigrid.py``; the coarse levels are Galerkin products of A, built once
    per scene and dt), in one kernel launch with the force residual and the update;
  - any other scene: conjugate gradients with A's Jacobi preconditioner, each solve to
    cg_tol relative to |g|.
Colliders act inside the iterations: their penalty and normal damping, against each
particle's plane linearised at the step's start (``Colliders.begin_solve``), are in the
force residual at every iterate, and their stiffness (k + c_d / h) n n^T is in A's
diagonal blocks for the particles within a collider's thickness at the iterate, so that
the global solve carries a collider's push through the springs to the whole cloth in
the step it lands (a projection after the iterations stopped only the particles that
touched, and the rest of a falling cloth tore itself on them). Along the normal only: a
frictionless collider takes no tangential momentum (with k + c_d / h in all three
directions, a cloth pushed along a frictionless floor hardly moved within the
iterations, and the step lost the momentum). Friction follows the iterations: against
each collider a particle touches, its approaching normal velocity is removed and its
tangential velocity cut by mu times the normal velocity change the contact force gave it
over the step (Coulomb).
A mesh collider's contact stage (``contact/obstacle.py``) keeps the step free of crossings
with half-spaces set for the motion the solve made; more iterations then pull the
particles below them onto them with a stiff penalty (``_hold``), so the springs take the
hold to the cloth around them instead of the guard moving the touching particles alone.
Pinned particles follow x0 + h v0.
"""
import numpy as np
import taichi as ti

from ..errors import SceneError
from ..model import grid as grid_layout
from .. import runtime
from .. import terms as term_modules
from ..terms.forces import Forces
from ..runtime import serial
from ..terms.colliders import Colliders
from ..terms.springs import grid_spring_sum, owned_grid_springs
from . import linalg
from .anderson import Anderson, check_depth
from .base import Integrator
from ..contact import PlaneConstraints
from .deflation import PlaneDeflation
from .multigrid import GridMultigrid, MultigridPCG, single_grid


@ti.data_oriented
class Projective(Integrator):
    """Liu et al. 2013 local/global solver. Options (defaults):

    iterations (10): local/global iterations per step.
    linear_solver ("auto"): "multigrid" (one V-cycle per global solve; only for a scene
        that is a single cloth grid, its default), "cg" (conjugate gradients, the default
        for every other scene).
    cg_tol (1e-3), cg_max_iterations (200): each CG global solve stops at cg_tol times
        |g| or after cg_max_iterations.
    anderson (0): the history of Anderson acceleration (``anderson.py``), 0 for Liu's
        plain iterations; with 5, a hundred iterations of a drape at one step per frame
        left a tenth of the plain ones' residual, in the same time (docs/realtime.md).
    planes (True): with self-collision, the contact stage's separating planes as one-sided
        constraints of the step (``contact/planes.py``: their forces in the residual,
        their stiffness in the global matrix), so that the iterate arrives without
        crossings; False leaves the contact work to the contact law's projection and to
        the guard after the step (which tore cloths thrown at each other at 10 m/s, a
        twisted cloth and the pile: ``docs/contact.md``).
    deflation (True): with the planes on a cloth grid, the global solves' CG deflates the
        active pairs' directions (``deflation.py``: a second level beside the V-cycle,
        which does not see the planes' couplings); False for the V-cycle alone.
    After each step ``stats`` holds iterations, cg_iterations (total, 0 with multigrid),
    residual: |g| at the last iteration relative to |g| at the first (how far the
    iterations got), anderson_restarts (the acceleration's history dropped),
    plane_pairs (the most vertex pairs the planes held at an iterate) and plane_cuts (the
    vertices whose first iterate was cut short at the planes).
    """
    name = "projective"
    defaults = {"iterations": 10, "linear_solver": "auto", "cg_tol": 1e-3,
                "cg_max_iterations": 200, "anderson": 0,
                "planes": True, "deflation": True}
    live_options = frozenset({"iterations", "cg_tol", "cg_max_iterations"})

    def __init__(self, model, contact=None, **options):
        super().__init__(model, contact, **options)
        depth = check_depth(self.options["anderson"])
        self.grid = single_grid(model, self.options["linear_solver"])
        # the model's fields, read by the kernels without being passed (Python launch time)
        self.mass, self.drag = model.mass, model.drag
        n, real = model.particle_count, runtime.real()
        self.x0, self.y, self.f = (ti.Vector.field(3, real, shape=n) for _ in range(3))
        # the terms by their treatment: in the force residual, in y, or projected after
        self.residual_forces = Forces(model, lambda cls: cls.projective == "force", contact)
        self.field_forces = Forces(model, lambda cls: cls.projective == "lagged", contact)
        self.has_field_forces = bool(self.field_forces.terms)
        self.projections = term_modules.build(model, lambda cls: cls.projective == "projection",
                                              contact)
        self.colliders = Colliders(model) if Colliders.present(model) else None
        self.has_colliders = self.colliders is not None
        # mesh colliders: the stage's half-spaces the iterations pull the cloth onto
        # after the solve (``_hold``, ``contact/hold.py``)
        self.hold = self.contact.hold if self.contact is not None else None
        self.has_hold = self.hold is not None
        self.deflation = None
        self.planes = (PlaneConstraints(n) if self.options["planes"]
                       and model.self_collision is not None else None)
        self.has_planes = self.planes is not None
        # one V-cycle an iteration on a grid without colliders or planes; else CG,
        # preconditioned by the V-cycle on a grid (the colliders' diagonal and the planes'
        # couplings change at every iterate)
        self.gridded = self.grid is not None
        self.vcycles = self.gridded and not (self.has_colliders or self.has_planes)
        self.stepped = ()
        if self.grid is not None:
            self.mg = GridMultigrid(self.grid.nx, self.grid.ny,
                                    grid_layout.stencil(self.grid.families), self.has_colliders)
        if self.vcycles:
            self.body = self.residual_forces.first
            self.grid_reals = model.grid_table.reals
            springs = self.residual_forces.springs
            self.grid_forces = (springs.grid_forces() if springs is not None else
                                ti.Vector.field(3, real, shape=(1, 6)))
            self.grid_mask = springs.mask if springs is not None else None    # tearing
        else:
            self.ks, self.kd = model.spring_ks, model.spring_kd
            springs = self.residual_forces.springs or term_modules.Springs(model)
            self.adj_start, self.adj = springs.adjacency()
            self.weight = ti.field(real, shape=self.adj.shape[0])
            # A's diagonal blocks (``linalg.symmetric6``) and block-Jacobi's inverses
            self.diag, self.precond = ti.Vector.field(6, real, n), ti.Matrix.field(3, 3, real, n)
            self.base_diag, self.row_rest, self.bound = (ti.field(real, n) for _ in range(3))
            # terms with a constant matrix (bending's Hessian, the membrane's bound)
            # enter A whole: their diagonal here, their couplings in CG's products
            self.constant = tuple(t.constant_matrix() for t in self.residual_forces.terms
                                  if t.has("constant_matrix"))
            # the pressure's stand-in changes with the step's start (``varies``: ``update``)
            self.stepped = tuple(m for m in self.constant if m.varies)
            couplings = self.constant + ((self.planes,) if self.has_planes else ())
            if self.grid is not None:
                self.solver = MultigridPCG(self.mg, n, self.diag, self.weight,
                                           self.adj_start, self.adj, model.inv_mass,
                                           couplings)
                if self.has_planes and not self.constant and self.options["deflation"]:
                    self.deflation = PlaneDeflation(self.solver)
                    self.solver.deflate(self.deflation)
            else:
                self.solver = linalg.PCG(n, self.diag, self.weight, self.adj_start, self.adj,
                                         self.precond, model.inv_mass, couplings)
        self.anderson = Anderson(n, depth) if depth else None
        self.stats = {}
        self._h = None
        self._t1 = None
        # step_residual's positions, velocities and residual
        self._probe = tuple(ti.Vector.field(3, real, shape=n) for _ in range(3))

    def parameters_changed(self):
        """Spring parameters or drag changed: the constant matrix is rebuilt."""
        super().parameters_changed()
        self._h = None

    def simulate(self, model, state_in, state_out, dt):
        h, t1 = dt, state_in.t + dt
        rebuilt = self._h != h
        if rebuilt:
            self._build_matrix(model, h)
            self._h = h
        if self.has_colliders:
            self.colliders.begin_solve(state_in.x, state_in.v, h, state_in.t)
        for matrix in self.stepped:
            matrix.update(state_in.x)
        x, v = state_out.x, state_out.v
        if self.has_field_forces:
            self.field_forces.compute(state_in.x, state_in.v, state_in.t, self.f)
        self._begin(state_in.x, state_in.v, h, x, v)
        cg_total, first, last = 0, None, None
        self._plane_pairs, self._plane_cuts = 0, 0
        if self.has_planes:
            self._begin_planes(state_in.x, x, v, h)
        aa = self.anderson
        if aa is not None:
            aa.start()
        if self.vcycles and self.mg.serial and aa is None:
            first, last = self._grid_iterations(x, v, h, self.options["iterations"])
        else:
            for _ in range(self.options["iterations"]):
                if aa is not None:
                    aa.keep(x)
                if self.vcycles:
                    last = self._grid_iteration(x, v, h)
                else:
                    self.residual_forces.compute(x, v, t1, self.f)
                    if self.has_planes:
                        self._hold_planes(state_in.x, x)
                    last = self._residual(x, v, h)
                    if last > 0.0:
                        iters, _ = self.solver.solve(self.options["cg_tol"],
                                                     self.options["cg_max_iterations"])
                        cg_total += iters
                        self._update(x, v, h)
                first = last if first is None else first
                if aa is not None and last > 0.0:
                    aa.mix(x, v, self.x0, h, last)
        hold_iterations = 0
        if self.has_hold:
            hold_iterations, iters = self._hold(state_in, x, v, h, t1)
            cg_total += iters
        if self.has_colliders:
            self._friction(x, v, h)
        for term in self.projections:
            term.project(x, v, t1)
        state_out.t = self._t1 = t1
        self.stats = {"iterations": self.options["iterations"], "cg_iterations": cg_total,
                      "residual": float(np.sqrt(last / first)) if first else 0.0,
                      "hold_iterations": hold_iterations,
                      "anderson_restarts": aa.restarts if aa is not None else 0,
                      "plane_pairs": self._plane_pairs, "plane_cuts": self._plane_cuts}

    def _begin_planes(self, x0, x, v, h):
        """The planes of the step (the stage's candidates of the motion from x0 to the
        first iterate x, ``ContactStage.search_solve``), and that iterate, x0 + h v0,
        cut short at their dividing planes (``ContactStage.truncate_solve``): two
        cloths thrown at each other at 10 m/s pass wholly through each other in it,
        every vertex pair of their candidates was active, and the first global solve,
        holding each at its plane, threw them 0.29 m apart."""
        self.contact.search_solve(x0, x, near=True)
        self._plane_cuts = self.contact.truncate_solve(x0, x, v)
        if self._plane_cuts:
            self._velocities(x, v, h)

    def _hold_planes(self, x0, x):
        """The planes' active vertex pairs at the iterate x and their forces into f
        (``contact/planes.py``), from the stage's candidates of the step's motion,
        searched again where an iterate leaves them (``ContactStage.follow_solve``)."""
        contacts = self.contact.follow_solve(x0, x)
        found = self.planes.gather(contacts, x, self.inv_mass, self.bound)
        if self.deflation is not None:
            self.deflation.prepare(self.planes.rows)
        self._plane_pairs = max(self._plane_pairs, found)
        self.planes.add_forces(x, self.f)

    @ti.kernel
    def _velocities(self, x: ti.template(), v: ti.template(), h: float):
        """v = (x - x0) / h, after the first iterate was cut short."""
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            v[p] = (x[p] - self.x0[p]) / h

    def _hold(self, state_in, x, v, h, t1):
        """Where the solve's motion ends below a mesh collider's half-spaces
        (``ContactStage.begin_hold``), ``iterations`` more with them as a stiff penalty
        (``Hold.pull``: its force in the residual, its isotropic bound on A's diagonal):
        the springs carry the hold to the cloth around, where the guard's projection
        after the step moved the touching particles alone (a cloth landing on a
        turntable's platter: its particles past the rim held up while their neighbours
        fell on, 4.6 J in the springs). Returns (iterations, CG iterations)."""
        if not self.contact.begin_hold(state_in.x, x, state_in.t, h):
            return 0, 0
        cg_total = 0
        for _ in range(self.options["iterations"]):
            self.residual_forces.compute(x, v, t1, self.f)
            if self._residual(x, v, h) > 0.0:
                iters, _ = self.solver.solve(self.options["cg_tol"],
                                             self.options["cg_max_iterations"])
                cg_total += iters
                self._update(x, v, h)
        self.contact.end_hold()
        return self.options["iterations"], cg_total

    def step_residual(self, x):
        """The force residual g (module docstring) of the step just taken, at positions x
        ((n, 3) NumPy) with the velocities (x - x0) / h: the step's equation, 0 at its
        solution (the friction and projections after the iterations aside). For studies
        of the step (its Jacobian, by central differences, says whether the step is convex)."""
        if self._h is None or "residual" not in self.stats:
            raise SceneError("step_residual reads the step just taken: take a step first")
        xs, vs, g = self._probe
        x = np.asarray(x, dtype=runtime.numpy_real())
        if x.shape != (g.shape[0], 3):
            raise SceneError(f"step_residual takes positions of shape ({g.shape[0]}, 3) "
                             f"(got x of shape {x.shape})")
        xs.from_numpy(x)
        vs.from_numpy((x - self.x0.to_numpy()) / self._h)
        self.residual_forces.compute(xs, vs, self._t1, self.f)
        self._residual_into(xs, vs, self._h, g)
        return g.to_numpy()

    @ti.kernel
    def _residual_into(self, x: ti.template(), v: ti.template(), h: float,
                       out: ti.template()):
        for p in range(x.shape[0]):
            out[p], _ = self._contact_residual(x, v, p, h)

    # -- the matrix ------------------------------------------------------------------------
    def _build_matrix(self, model, h):
        if self.grid is not None:
            weights = self._grid_weights(model, h)
            self.mg.set_matrix(weights)
            self.mg.set_fine_base(weights[..., self.mg.stencil.index((0, 0))])
        if not self.vcycles:
            for term in self.constant:
                term.set_step(h)
            self._build_adjacency_matrix(h)

    def _grid_weights(self, model, h):
        """A as stencil weights (ny, nx, len(stencil)) on the grid, pinned particles'
        rows and columns 0."""
        g = self.grid
        stencil = self.mg.stencil
        slot = {offset: k for k, offset in enumerate(stencil)}
        slot_of = np.full(25, -1, dtype=np.int64)     # (di + 2) * 5 + dj + 2 -> slot
        for (di, dj), k in slot.items():
            slot_of[(di + 2) * 5 + dj + 2] = k
        ns = model.spring_count
        pairs = model.spring_pairs.to_numpy()[:ns].astype(np.int64)
        w = model.spring_ks.to_numpy()[:ns] + model.spring_kd.to_numpy()[:ns] / h
        ja, ia = np.divmod(pairs[:, 0], g.nx)
        jb, ib = np.divmod(pairs[:, 1], g.nx)
        free = model.inv_mass.to_numpy() > 0
        coupled = w * (free[pairs[:, 0]] & free[pairs[:, 1]])    # 0 towards a pinned end
        weights = np.zeros((g.ny, g.nx, len(stencil)))
        diag = (model.mass.to_numpy() / h ** 2 + model.drag.to_numpy() / h).reshape(g.ny, g.nx)
        for (j, i), (dj, di) in (((ja, ia), (jb - ja, ib - ia)), ((jb, ib), (ja - jb, ia - ib))):
            np.add.at(weights, (j, i, slot_of[(di + 2) * 5 + dj + 2]), -coupled)
            np.add.at(diag, (j, i), w)
        weights[..., slot[(0, 0)]] = diag
        weights[~free.reshape(g.ny, g.nx)] = 0.0
        return weights

    @ti.kernel
    def _build_adjacency_matrix(self, h: float):
        """A as per-particle diagonal and per-entry weights, and its inverse diagonal (the
        colliders' weights are added at each iteration: ``_set_diagonal``)."""
        ti.loop_config(serialize=ti.static(serial(self.diag)))
        for p in range(self.diag.shape[0]):
            self.base_diag[p] = self.mass[p] / (h * h) + self.drag[p] / h
            for term in ti.static(self.constant):
                self.base_diag[p] += term.diagonal[p]
            self.row_rest[p] = 0.0
            for k in range(self.adj_start[p], self.adj_start[p + 1]):
                s = self.adj[k][0]
                self.weight[k] = self.ks[s] + self.kd[s] / h
                self.row_rest[p] += self.weight[k]
            self.bound[p] = self.base_diag[p] + self.row_rest[p]
            self._set_diagonal(p, ti.Matrix.zero(float, 3, 3))

    @ti.func
    def _set_diagonal(self, p, extra):
        """A's diagonal block at particle p with the 3 x 3 ``extra`` added (the stiffness
        of the contacts active at the iterate), and its block-Jacobi preconditioner (where
        no V-cycle preconditions)."""
        block = self.base_diag[p] * ti.Matrix.identity(float, 3) + extra
        self.diag[p] = linalg.symmetric6(block)
        if ti.static(not self.gridded):
            if self.inv_mass[p] > 0.0:
                self.precond[p] = (block + self.row_rest[p]
                                   * ti.Matrix.identity(float, 3)).inverse()

    # -- the iterations -------------------------------------------------------------------
    @ti.kernel
    def _begin(self, x_in: ti.template(), v_in: ti.template(), h: float, x: ti.template(),
               v: ti.template()):
        """x0; Liu's y = x0 + h v0 + h^2 M^-1 f with f the wind and attraction in self.f
        (evaluated at the start of the step; pinned, or a scene without them: x0 + h v0);
        the first iterate x0 + h v0 (a cloth at rest in equilibrium is then a fixed point
        whatever the iterations)."""
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            self.x0[p] = x_in[p]
            x[p] = x_in[p] + h * v_in[p]
            v[p] = v_in[p]
            self.y[p] = x[p]
            if ti.static(self.has_field_forces):
                self.y[p] += h * h * self.inv_mass[p] * self.f[p]


    @ti.func
    def _force_residual(self, x, v, p, f, h):
        """g_p = m/h^2 (y - x) + f + the colliders' normal force against the particle's
        planes (0 on pinned particles)."""
        g = ti.Vector.zero(float, 3)
        if self.inv_mass[p] > 0.0:
            g = self.mass[p] / (h * h) * (self.y[p] - x[p]) + f
            if ti.static(self.has_colliders):
                g += self.colliders.plane_force(p, x, v)
        return g

    @ti.func
    def _contact_residual(self, x, v, p, h):
        """(g_p with the mesh colliders' hold, the 3 x 3 stiffness of p's active contacts
        and hold on A's diagonal; 0 without colliders): the residual of the CG path."""
        g = self._force_residual(x, v, p, self.f[p], h)
        w = ti.Matrix.zero(float, 3, 3)
        if ti.static(self.has_colliders):
            w = self.colliders.plane_stiffness(p, x)
            if ti.static(self.has_hold):
                f_hold, w_hold = self.hold.pull(p, x)
                g += f_hold
                w += w_hold * ti.Matrix.identity(float, 3)
        return g, w

    @ti.kernel
    def _friction(self, x: ti.template(), v: ti.template(), h: float):
        """Coulomb friction after the iterations (module docstring), on the velocities (the
        positions are the solve's): the normal velocity change is the contact force's
        impulse h |f_n| / m."""
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            if self.inv_mass[p] > 0.0:
                fn = self.colliders.plane_force(p, x, v)
                self.colliders.plane_coulomb(p, x, v, h * fn.norm() * self.inv_mass[p])

    @ti.kernel
    def _grid_iteration(self, x: ti.template(), v: ti.template(), h: float) -> ti.f64:
        return self._grid_iteration_loops(x, v, h)

    @ti.kernel
    def _grid_iterations(self, x: ti.template(), v: ti.template(), h: float,
                         n: ti.i32) -> ti.types.vector(2, ti.f64):
        """n iterations in one launch, where every loop runs on one thread (each launch
        costs Python time); |g|^2 at the first and the last."""
        first = ti.cast(0.0, ti.f64)
        last = ti.cast(0.0, ti.f64)
        ti.loop_config(serialize=True)
        for it in range(n):
            last = self._grid_iteration_loops(x, v, h)
            if it == 0:
                first = last
        return ti.Vector([first, last], ti.f64)

    @ti.func
    def _grid_iteration_loops(self, x, v, h):
        """One iteration on the grid: the spring stencil (``forces.py``), gravity and drag
        into the force residual g, a V-cycle, the update x += B g, v = (x - x0) / h.
        Returns |g|^2."""
        ny, nx = ti.static(self.mg.shapes[0])
        families = ti.static(self.grid.families)
        owned_grid_springs(x, v, 0, nx, ny, self.grid_reals[0], families, self.grid_forces,
                           self.grid_mask)
        total = ti.cast(0.0, ti.f64)
        ti.loop_config(serialize=ti.static(self.mg.serial))
        for j, i in ti.ndrange(ny, nx):
            p = j * nx + i
            f = (self.body.force(p, x, v, 0.0)
                 + grid_spring_sum(0, nx, ny, i, j, families, self.grid_forces))
            g = self._force_residual(x, v, p, f, h)
            self.mg.set_rhs(j, i, g)
            total += ti.cast(g.dot(g), ti.f64)
        self.mg.cycle()
        ti.loop_config(serialize=ti.static(self.mg.serial))
        for j, i in ti.ndrange(ny, nx):
            p = j * nx + i
            x[p] += self.mg.result(j, i)
            v[p] = (x[p] - self.x0[p]) / h
        return total

    @ti.kernel
    def _residual(self, x: ti.template(), v: ti.template(), h: float) -> ti.f64:
        """The force residual into the CG right-hand side. Returns |g|^2."""
        total = ti.cast(0.0, ti.f64)
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            g, w = self._contact_residual(x, v, p, h)
            if ti.static(self.has_colliders):
                self._set_diagonal(p, w)
                if ti.static(self.gridded):
                    self.mg.set_fine_diagonal(p // self.grid.nx, p % self.grid.nx,
                                              ti.Vector([w[0, 0], w[1, 1], w[2, 2]]))
            self.solver.b[p] = g
            total += ti.cast(g.dot(g), ti.f64)
        return total

    @ti.kernel
    def _update(self, x: ti.template(), v: ti.template(), h: float):
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            x[p] += self.solver.x[p]
            v[p] = (x[p] - self.x0[p]) / h
