"""Backward Euler (Baraff & Witkin 1998), solved as a minimisation with Newton's method.

One step of size h finds the end positions x (and v = (x - x0) / h) that minimise the
incremental potential

    E(x) = 1/(2 h^2) |x - x0 - h v0|_M^2 + U(x) + D(x) - f_lag . x

U: springs k_s/2 (|x_ij| - l0)^2, gravity -m g . x, collider penalties k/2 depth^2.
D: dissipation, with directions frozen at the start of the step: spring damping
   k_d / (2h) ((x_ij - x0_ij) . d0)^2, air drag c / (2h) |x - x0|^2, contact normal damping
   for particles approaching a collider, and Coulomb friction as the convex potential
   mu fn0 h psi(|v_t|) (psi' = min(|v_t| / eps, 1)) with the normal force fn0 and normal of
   the start of the step, which gives exactly the explicit friction law at the end velocity.
f_lag: wind and attraction, evaluated at the start of the step (explicit).

grad E = 0 is backward Euler. Newton's method: each Newton step solves H dx = -grad E by
conjugate gradients, filtered so that pinned particles do not move (Baraff & Witkin's
filtered CG); a backtracking line search on E makes every iteration decrease E (or
change it by less than its rounding error), so a step never gains energy. H is assembled
as symmetric 3 x 3 blocks in Taichi kernels:
  - blocks per spring end, gathered per particle, with a block-Jacobi (3 x 3 per
    particle) preconditioner;
  - or, for a scene that is one cloth grid and nothing else (``linear_solver``), as
    block stencil weights on the grid, with a geometric multigrid V-cycle (Galerkin
    coarse levels built at each step's first Newton iteration, block Gauss-Seidel
    smoothing; ``multigrid.py``) as the CG preconditioner: a few CG iterations per
    solve however the cloth folds.
Compressed springs make H indefinite: their transverse stiffness k (1 - l0/|x_ij|) is
negative. The definiteness fix clamps it at 0 (the projected H, positive definite). With
the line search (the default) CG multiplies by the exact H instead, preconditioned by
the projected one, and stops at the first direction of non-positive curvature with a
descent direction (truncated Newton-CG, ``linalg.ConjugateGradients``). The step's
solution is a minimum of E, where the exact H is positive semi-definite, so Newton
converges quadratically there; on the projected H it converges linearly once the cloth
folds (on the 128 x 128 benchmark cloth 6 Newton iterations a step over the swing
instead of 3; ``test_newton_on_the_exact_hessian_converges_quadratically_on_folded_cloth``).
``newton_iterations=1, line_search=False`` is Baraff & Witkin's single linearised solve,
on the projected H: a full step along a truncated direction can gain energy without
bound (the benchmark cloth blew up).
"""
import numpy as np
import taichi as ti

from .. import runtime
from ..colliders import signed_distance
from ..errors import SceneError
from ..forces import eval_attraction, eval_wind, grid_rest_lengths, rest_length, OWNED
from ..runtime import serial
from . import linalg, multigrid
from .base import Integrator


@ti.data_oriented
class BackwardEuler(Integrator):
    """Implicit Euler by Newton + preconditioned CG. Options (defaults):

    newton_iterations (8): maximum Newton iterations per step.
    newton_tol (1e-4): stop when an iteration changes no velocity by more than
        newton_tol * (1 m/s + max |v0|).
    cg_tol (1e-2): CG stops at this residual relative to the right-hand side. An inexact
        Newton step: the converged result is set by newton_tol (measured on the 128 x 128
        benchmark cloth: 1e-2 lands as close to a 1e-6/1e-6 reference as 1e-4 does, with
        half the CG iterations; docs/implicit.md).
    cg_max_iterations (500).
    line_search (True): backtracking on E (Armijo); False takes full Newton steps.
    exact_hessian (None: the same as line_search): CG on the exact Hessian, stopped at
        negative curvature and preconditioned by the projected one (needs the line
        search), or on the projected Hessian (the definiteness fix).
    linear_solver ("auto"): the CG preconditioner, "multigrid" (only for a scene that is a
        single cloth grid) or "cg" (block Jacobi). "auto" takes the multigrid for a
        single cloth grid and block Jacobi otherwise. On the benchmark cloth over its
        swing: one linearised solve 3 CG iterations a step against 62; Newton on the
        exact Hessian 12 against 108, 0.6-0.7x the time before the cloth folds and about
        the same after (128 x 128), 0.72x over 1.5 s at 256 x 256, with a longer tail
        (docs/implicit.md).

    After each step ``stats`` holds newton_iterations, cg_iterations (total) and
    residual (the last CG relative residual).
    """
    name = "backward_euler"
    defaults = {"newton_iterations": 8, "newton_tol": 1e-4, "cg_tol": 1e-2,
                "cg_max_iterations": 500, "line_search": True, "linear_solver": "auto",
                "exact_hessian": None}

    def __init__(self, model, **options):
        super().__init__(model, **options)
        n, real = model.particle_count, runtime.real()
        self.x_hat, self.x0, self.grad, self.f_lag, self.x_try = (
            ti.Vector.field(3, real, shape=n) for _ in range(5))
        springs = max(model.spring_count, 1)
        self.d0, self.g_spring = (ti.Vector.field(3, real, shape=springs) for _ in range(2))
        self.adj_start, self.adj = model.adjacency()
        exact = self.options["exact_hessian"]
        line_search = self.options["line_search"]
        if exact not in (None, True, False):
            raise SceneError(f"exact_hessian must be None, True or False (got {exact!r})")
        if exact and not line_search:
            raise SceneError("exact_hessian=True needs line_search=True: without it a step "
                             "along a direction of negative curvature can gain energy")
        self.exact = line_search if exact is None else exact
        self.grid = multigrid.single_grid(model, self.options["linear_solver"])
        if self.grid is not None:
            self.grid_reals = model.grid_reals
            self.mg = multigrid.BlockGridMultigrid(
                self.grid.nx, self.grid.ny, multigrid.grid_stencil(self.grid.families))
            self.solver = multigrid.GridPCG(self.mg, own_matrix=self.exact)
            self.dx = ti.Vector.field(3, real, shape=n)
        else:
            self.diag = ti.Vector.field(6, real, shape=n)
            self.precond = ti.Matrix.field(3, 3, real, shape=n)
            self.blocks = ti.Vector.field(6, real, shape=self.adj.shape[0])
            self.solver = linalg.PCG(n, self.diag, self.blocks, self.adj_start, self.adj,
                                     self.precond, model.inv_mass)
            self.dx = self.solver.x
        c = max(model.collider_count, 1)
        self.fn0 = ti.field(real, shape=(n, c))
        self.n0 = ti.Vector.field(3, real, shape=(n, c))
        self.acc = ti.field(runtime.accumulator(), shape=2)     # E, sum of |terms|
        self._eps = float(np.finfo(runtime.numpy_real()).eps)
        self.stats = {}
        self._lagged = model.wind is not None or model.attraction is not None

    # -- the step ------------------------------------------------------------------------
    def simulate(self, model, state_in, state_out, dt):
        h, t1 = dt, state_in.t + dt
        opt = self.options
        x = state_out.x
        self._begin(model, state_in.x, state_in.v, h, state_in.t, x)
        if self._lagged:
            self.f_lag.fill(0)
            if model.wind is not None:
                eval_wind(state_in.x, state_in.v, model.triangles, model.wind_params,
                          state_in.t, self.f_lag)
            if model.attraction is not None:
                eval_attraction(state_in.x, model.mass, *model.attraction, self.f_lag)
        cg_total, residual, it = 0, 0.0, 0
        tol = opt["newton_tol"] * (1.0 + linalg.max_norm(state_in.v))
        energy = self._energy_and_gradient(model, x, h, t1)
        for it in range(1, opt["newton_iterations"] + 1):
            iters, residual = self._solve(model, x, h, t1, first=it == 1)
            cg_total += iters
            size = linalg.max_norm(self.dx) / h              # a full step's velocity change
            last = it == opt["newton_iterations"] or size < tol
            alpha = 1.0
            if opt["line_search"]:
                alpha, energy = self._line_search(model, x, h, t1, energy, not last)
            linalg.axpy_into(x, x, alpha, self.dx)           # = x_try, bit for bit
            if last or alpha * size < tol:
                break
            if not opt["line_search"]:
                energy = self._energy_and_gradient(model, x, h, t1)
        self._finish(state_in.x, x, 1.0 / h, state_out.v)
        state_out.t = t1
        self.stats = {"newton_iterations": it, "cg_iterations": cg_total, "residual": residual}

    def _line_search(self, model, x, h, t, energy, with_grad):
        """Backtracking from alpha = 1 along dx until E falls by the Armijo fraction 1e-4
        of the slope, or by less than E's rounding error (near convergence the decrease is
        below it, and the test would compare rounding); alpha >= 2^-14. Each trial also
        computes the gradient when ``with_grad``, so that the accepted one is the next
        iteration's (the gradient at x is not needed once the slope is known). Returns
        (alpha, E at x + alpha dx)."""
        slope = linalg.dot(self.grad, self.dx)
        alpha = 1.0
        while True:
            linalg.axpy_into(self.x_try, x, alpha, self.dx)
            trial, rounding = self._terms(model, self.x_try, h, t, with_grad)
            if trial <= energy + 1e-4 * alpha * slope + rounding or alpha < 1e-4:
                return alpha, trial
            alpha *= 0.5

    def _solve(self, model, x, h, t, first=True):
        """Preconditioned CG on H dx = -grad (filtered: pinned entries stay 0). The
        multigrid's coarse levels are built at the step's first Newton iteration and kept
        for the others (a preconditioner need not follow every iterate: on the 128 x 128
        benchmark cloth 35 instead of 40 ms per Newton iteration, as many CG iterations)."""
        self._assemble(model, x, h, t, coarse=first)
        if self.grid is None:
            linalg.scale_into(self.solver.b, -1.0, self.grad)
        else:
            self._grid_rhs(model.inv_mass)
        result = self.solver.solve(self.options["cg_tol"], self.options["cg_max_iterations"])
        if self.grid is not None:
            self._grid_solution()
        return result

    # -- energy, gradient, Hessian products (Python wrappers) ------------------------------
    def _energy_and_gradient(self, model, x, h, t):
        return self._terms(model, x, h, t, True)[0]

    def _terms(self, model, x, h, t, with_grad):
        """(E at x, a bound on the rounding error of comparing two such evaluations:
        8 ulps of the sum of the terms' magnitudes); the gradient into ``grad`` when
        ``with_grad``."""
        self._particle_terms(x, model.mass, model.inv_mass, model.params, h, with_grad)
        if model.spring_count:
            self._spring_terms(x, model.spring_pairs, model.spring_ks, model.spring_kd,
                               model.spring_rest, model.spring_count, h, with_grad)
        if model.collider_count:
            self._contact_terms(x, model.inv_mass, model.collider_records,
                                model.collider_ranges, h, t, with_grad)
        energy, magnitude = self._sums()
        return energy, 8.0 * self._eps * magnitude

    @ti.kernel
    def _sums(self) -> ti.types.vector(2, ti.f64):
        return ti.Vector([self.acc[0], self.acc[1]], ti.f64)

    def _assemble(self, model, x, h, t, coarse=True):
        """Hessian blocks at positions x: on the grid with its multigrid levels (the coarse
        ones only when ``coarse``), or per spring end and per particle (inertia, drag and
        contacts) with the inverse diagonal blocks (block-Jacobi preconditioner)."""
        if self.grid is not None:
            self._assemble_grid(x, model.mass, model.inv_mass, model.params,
                                model.collider_records, model.collider_ranges, h, t)
            self.mg.build(coarse)
        else:
            self._assemble_blocks(x, model.mass, model.inv_mass, model.params,
                                  model.spring_pairs, model.spring_ks, model.spring_kd,
                                  model.spring_rest, model.spring_count,
                                  model.collider_records, model.collider_ranges, h, t)

    def hessian_product(self, model, x, p, h, t=0.0):
        """H p at positions x (fields); for tests and tools. Returns (N,3) NumPy."""
        self._assemble(model, x, h, t)
        if self.grid is not None:
            shape = self.mg.shapes[0] + (3,)
            return self.solver.product(p.to_numpy().reshape(shape)).reshape(-1, 3)
        self.solver.apply(p, self.solver.ap)
        return self.solver.ap.to_numpy()

    # -- kernels: set-up and finish ------------------------------------------------------
    @ti.kernel
    def _begin_particles(self, x: ti.template(), v: ti.template(), h: float,
                         x_start: ti.template()):
        """x0, the inertial prediction x_hat = x0 + h v0, and the Newton start x_hat."""
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            self.x0[p] = x[p]
            self.x_hat[p] = x[p] + h * v[p]
            x_start[p] = self.x_hat[p]

    @ti.kernel
    def _begin_springs(self, x: ti.template(), pairs: ti.template(), count: ti.i32):
        ti.loop_config(serialize=ti.static(serial(pairs)))
        for s in range(count):
            d = x[pairs[s][0]] - x[pairs[s][1]]
            self.d0[s] = d / ti.max(d.norm(), 1e-30)

    @ti.kernel
    def _begin_contacts(self, x: ti.template(), inv_mass: ti.template(),
                        records: ti.template(), ranges: ti.template(), t: float):
        """Lagged normal force and normal of each (particle, collider) contact."""
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            for kind in ti.static(range(3)):
                if ti.static(ranges[kind][1] > 0):
                    for c in range(ranges[kind][0], ranges[kind][0] + ranges[kind][1]):
                        rec = records[c]
                        phi, n = signed_distance(kind, rec, x[p], t)
                        depth = rec[18] - phi
                        fn = 0.0
                        if depth > 0.0 and inv_mass[p] > 0.0:
                            fn = rec[19] * depth
                        self.fn0[p, c] = fn
                        self.n0[p, c] = n

    def _begin(self, model, x, v, h, t0, x_start):
        self._begin_particles(x, v, h, x_start)
        if model.spring_count:
            self._begin_springs(x, model.spring_pairs, model.spring_count)
        if model.collider_count:
            self._begin_contacts(x, model.inv_mass, model.collider_records,
                                 model.collider_ranges, t0)

    @ti.kernel
    def _finish(self, x0: ti.template(), x: ti.template(), inv_h: float, v_out: ti.template()):
        """v = (x - x0) / h; pinned particles keep v0 since their x = x0 + h v0."""
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            v_out[p] = (x[p] - x0[p]) * inv_h

    # -- kernels: energy and gradient ------------------------------------------------------
    @ti.kernel
    def _particle_terms(self, x: ti.template(), mass: ti.template(), inv_mass: ti.template(),
                        params: ti.template(), h: float, with_grad: ti.template()):
        """Inertia, gravity, air drag and lagged forces; the first of E's kernels (sets acc
        to 0)."""
        self.acc[0] = 0.0
        self.acc[1] = 0.0
        gravity = ti.Vector([params[0], params[1], params[2]])
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            m = mass[p]
            dxh = x[p] - self.x_hat[p]
            dx0 = x[p] - self.x0[p]
            e_pos = 0.5 * m / (h * h) * dxh.dot(dxh) + 0.5 * params[3] / h * dx0.dot(dx0)
            e_lin = -m * gravity.dot(x[p])
            g = m / (h * h) * dxh - m * gravity + params[3] / h * dx0
            if ti.static(self._lagged):
                e_lin -= self.f_lag[p].dot(x[p])
                g -= self.f_lag[p]
            if inv_mass[p] > 0.0:
                self.acc[0] += ti.cast(e_pos + e_lin, self.acc.dtype)
                self.acc[1] += ti.cast(e_pos + ti.abs(e_lin), self.acc.dtype)
            if ti.static(with_grad):
                self.grad[p] = g

    @ti.kernel
    def _spring_terms(self, x: ti.template(), pairs: ti.template(), ks: ti.template(),
                      kd: ti.template(), rest: ti.template(), count: ti.i32, h: float,
                      with_grad: ti.template()):
        """Spring energy k/2 (l - l0)^2 and frozen-direction damping k_d/(2h) (dx_ij.d0)^2;
        gradients per spring, then gathered per particle."""
        ti.loop_config(serialize=ti.static(serial(pairs)))
        for s in range(count):
            i, j = pairs[s][0], pairs[s][1]
            d = x[i] - x[j]
            length = d.norm()
            n = d / ti.max(length, 1e-30)
            stretch = length - rest[s]
            rel = (d - (self.x0[i] - self.x0[j])).dot(self.d0[s])
            e = 0.5 * ks[s] * stretch * stretch + 0.5 * kd[s] / h * rel * rel
            self.acc[0] += ti.cast(e, self.acc.dtype)
            self.acc[1] += ti.cast(e, self.acc.dtype)
            if ti.static(with_grad):
                self.g_spring[s] = ks[s] * stretch * n + kd[s] / h * rel * self.d0[s]
        if ti.static(with_grad):
            ti.loop_config(serialize=ti.static(serial(x)))
            for p in range(x.shape[0]):
                g = ti.Vector.zero(float, 3)
                for k in range(self.adj_start[p], self.adj_start[p + 1]):
                    s = self.adj[k][0]
                    sign = 1.0 if pairs[s][0] == p else -1.0
                    g += sign * self.g_spring[s]
                self.grad[p] += g

    @ti.func
    def _contact_one(self, kind: ti.template(), rec, xp, p, c, m, h, t):
        """(energy, gradient) of one particle against one collider: penalty k/2 depth^2 at
        x, normal damping and friction with the start-of-step normal and force."""
        phi, n = signed_distance(kind, rec, xp, t)
        depth = rec[18] - phi
        e = 0.0
        g = ti.Vector.zero(float, 3)
        k = rec[19]
        if depth > 0.0:
            e += 0.5 * k * depth * depth
            g -= k * depth * n
        fn0 = self.fn0[p, c]
        if fn0 > 0.0:
            n0 = self.n0[p, c]
            v = (xp - self.x0[p]) / h - ti.Vector([rec[3], rec[4], rec[5]])
            vn = v.dot(n0)
            if vn < 0.0:
                cd = 2.0 * rec[20] * ti.sqrt(k * m)
                e += 0.5 * cd * h * vn * vn
                g += cd * vn * n0
            vt = v - vn * n0
            s = vt.norm()
            mu, eps = rec[21], rec[22]
            if s < eps:
                e += mu * fn0 * h * s * s / (2.0 * eps)
                g += mu * fn0 / eps * vt
            else:
                e += mu * fn0 * h * (s - 0.5 * eps)
                g += mu * fn0 / s * vt
        return e, g

    @ti.kernel
    def _contact_terms(self, x: ti.template(), inv_mass: ti.template(), records: ti.template(),
                       ranges: ti.template(), h: float, t: float, with_grad: ti.template()):
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            if inv_mass[p] > 0.0:
                for kind in ti.static(range(3)):
                    if ti.static(ranges[kind][1] > 0):
                        for c in range(ranges[kind][0], ranges[kind][0] + ranges[kind][1]):
                            e, g = self._contact_one(kind, records[c], x[p], p, c,
                                                     1.0 / inv_mass[p], h, t)
                            self.acc[0] += ti.cast(e, self.acc.dtype)
                            self.acc[1] += ti.cast(e, self.acc.dtype)
                            if ti.static(with_grad):
                                self.grad[p] += g

    # -- kernels: Hessian products and preconditioner ------------------------------------
    @ti.func
    def _spring_blocks(self, xi, xj, ks, kd, rest, d0, h):
        """The 3x3 Hessian block of one spring, exact and made positive semi-definite
        (transverse stiffness k (1 - l0/|x_ij|), negative under compression, clamped at 0)."""
        d = xi - xj
        length = d.norm()
        n = d / ti.max(length, 1e-30)
        nn = n.outer_product(n)
        transverse = 1.0 - rest / ti.max(length, 1e-30)
        eye = ti.Matrix.identity(float, 3)
        exact = ks * (nn + transverse * (eye - nn)) + kd / h * d0.outer_product(d0)
        return exact, exact + ks * ti.max(-transverse, 0.0) * (eye - nn)

    @ti.func
    def _contact_block(self, kind: ti.template(), rec, xp, p, c, m, h, t):
        """3x3 Hessian block of one contact (penalty k n n^T without the curvature term,
        normal damping, friction)."""
        phi, n = signed_distance(kind, rec, xp, t)
        block = ti.Matrix.zero(float, 3, 3)
        k = rec[19]
        if rec[18] - phi > 0.0:
            block += k * n.outer_product(n)
        fn0 = self.fn0[p, c]
        if fn0 > 0.0:
            n0 = self.n0[p, c]
            nn = n0.outer_product(n0)
            v = (xp - self.x0[p]) / h - ti.Vector([rec[3], rec[4], rec[5]])
            vn = v.dot(n0)
            if vn < 0.0:
                block += 2.0 * rec[20] * ti.sqrt(k * m) / h * nn
            vt = v - vn * n0
            s = vt.norm()
            mu, eps = rec[21], rec[22]
            tangent = ti.Matrix.identity(float, 3) - nn
            if s < eps:
                block += mu * fn0 / (eps * h) * tangent
            else:
                that = vt / s
                block += mu * fn0 / (s * h) * (tangent - that.outer_product(that))
        return block

    @ti.func
    def _contact_blocks(self, x, inv_mass, records, ranges: ti.template(), p, h, t):
        """Sum of the contact Hessian blocks of particle p (zero when pinned)."""
        block = ti.Matrix.zero(float, 3, 3)
        if inv_mass[p] > 0.0:
            for kind in ti.static(range(3)):
                if ti.static(ranges[kind][1] > 0):
                    for c in range(ranges[kind][0], ranges[kind][0] + ranges[kind][1]):
                        block += self._contact_block(kind, records[c], x[p], p, c,
                                                     1.0 / inv_mass[p], h, t)
        return block

    @ti.kernel
    def _assemble_blocks(self, x: ti.template(), mass: ti.template(), inv_mass: ti.template(),
                         params: ti.template(), pairs: ti.template(), ks: ti.template(),
                         kd: ti.template(), rest: ti.template(), count: ti.i32,
                         records: ti.template(), ranges: ti.template(), h: float, t: float):
        """Each spring's block (exact or projected, see ``exact_hessian``) at both of its
        ends' adjacency entries, so that the CG products read them in order; the
        preconditioner from the projected blocks."""
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            block = ((mass[p] / (h * h) + params[3] / h) * ti.Matrix.identity(float, 3)
                     + self._contact_blocks(x, inv_mass, records, ranges, p, h, t))
            self.diag[p] = linalg.symmetric6(block)
            for k in range(self.adj_start[p], self.adj_start[p + 1]):
                s, q = self.adj[k][0], self.adj[k][1]
                exact, projected = self._spring_blocks(x[p], x[q], ks[s], kd[s], rest[s],
                                                       self.d0[s], h)
                self.blocks[k] = linalg.symmetric6(exact if ti.static(self.exact)
                                                   else projected)
                block += projected
            self.precond[p] = block.inverse()

    @ti.kernel
    def _assemble_grid(self, x: ti.template(), mass: ti.template(), inv_mass: ti.template(),
                       params: ti.template(), records: ti.template(), ranges: ti.template(),
                       h: float, t: float):
        """The Hessian as the grid's block stencil weights: at the centre each particle's
        inertia, drag, contact and spring blocks, at the other end of each spring it
        stores (``multigrid.half_stencil``) minus its block; pinned particles' rows and
        columns 0. The multigrid gets the projected spring blocks, CG the exact ones
        (``exact_hessian``)."""
        ny, nx = ti.static(self.mg.shapes[0])
        stencil, half = ti.static(self.mg.stencil, self.mg.halves[0])
        g = self.grid_reals[0]
        rest = grid_rest_lengths(g)
        ti.loop_config(serialize=ti.static(self.mg.serial))
        for j, i in ti.ndrange(ny, nx):
            p = j * nx + i
            free = ti.cast(inv_mass[p] > 0.0, float)
            centre = ((mass[p] / (h * h) + params[3] / h) * ti.Matrix.identity(float, 3)
                      + self._contact_blocks(x, inv_mass, records, ranges, p, h, t))
            centre_exact = centre
            for k in ti.static(range(1, len(stencil))):
                di, dj = ti.static(stencil[k])
                fam = ti.static(_family(di, dj))
                stored = ti.static((di, dj) in half)
                coupling = ti.Matrix.zero(float, 3, 3)
                coupling_exact = ti.Matrix.zero(float, 3, 3)
                if 0 <= i + di < nx and 0 <= j + dj < ny:
                    q = (j + dj) * nx + i + di
                    d0 = self.x0[p] - self.x0[q]
                    exact, projected = self._spring_blocks(
                        x[p], x[q], g[2 + fam], g[5 + fam], rest_length(rest, di, dj),
                        d0 / ti.max(d0.norm(), 1e-30), h)
                    centre += projected
                    centre_exact += exact
                    if ti.static(stored):
                        if inv_mass[q] > 0.0:
                            coupling = -projected
                            coupling_exact = -exact
                if ti.static(stored):
                    k_half = ti.static(half.index((di, dj)))
                    self.mg.set_block(j, i, k_half, free * linalg.symmetric6(coupling))
                    if ti.static(self.exact):
                        self.solver.set_block(j, i, k_half,
                                              free * linalg.symmetric6(coupling_exact))
            self.mg.set_block(j, i, 0, free * linalg.symmetric6(centre))
            if ti.static(self.exact):
                self.solver.set_block(j, i, 0, free * linalg.symmetric6(centre_exact))

    @ti.kernel
    def _grid_rhs(self, inv_mass: ti.template()):
        """-grad E into the multigrid CG's right-hand side (0 at pinned particles)."""
        ny, nx = ti.static(self.mg.shapes[0])
        ti.loop_config(serialize=ti.static(self.mg.serial))
        for j, i in ti.ndrange(ny, nx):
            p = j * nx + i
            g = ti.Vector.zero(float, 3)
            if inv_mass[p] > 0.0:
                g = -self.grad[p]
            self.mg.set_rhs(j, i, g)

    @ti.kernel
    def _grid_solution(self):
        ny, nx = ti.static(self.mg.shapes[0])
        ti.loop_config(serialize=ti.static(self.mg.serial))
        for j, i in ti.ndrange(ny, nx):
            self.dx[j * nx + i] = self.solver.x[j + multigrid.PAD, i + multigrid.PAD]


def _family(di, dj):
    """The spring family of grid offset (di, dj) (``OWNED``)."""
    return next(f for f, owned in enumerate(OWNED) if (di, dj) in owned or (-di, -dj) in owned)
