"""Projective dynamics for mass-spring systems: the local/global solver of Liu, Bargteil,
O'Brien & Kavan 2013, "Fast Simulation of Mass-Spring Systems".

A backward Euler step minimises 1/(2h^2) |x - y|_M^2 + sum_s k_s/2 |x_i - x_j - d_s|^2
over positions x and spring directions d_s with |d_s| = l0_s, alternating
  local:  d_s = l0_s (x_i - x_j) / |x_i - x_j|            (every spring in parallel)
  global: (M/h^2 + c/h + L) x = M/h^2 y + c/h x0 + J d     (one constant matrix)
with y = x0 + h v0 + h^2 M^-1 f_ext: gravity, wind and attraction enter explicitly at the
start of the step, air drag c implicitly. L = sum_s k_s A_s A_s^T is constant, so its
Jacobi preconditioner is built once per scene; each global solve is warm-started CG with
matrix products gathered per particle (no atomics).
Spring damping k_d enters as the constant Laplacian term k_d/h A_s A_s^T (damping of the
relative velocity of the two ends in all directions, a simplification of the axial
damping of the other integrators, which keeps the matrix constant). It acts like a viscous
medium: on a damped swinging cloth it is 30 times further from the true motion than
backward Euler, whereas with k_d = 0 the two agree (docs/benchmarks.md). Prefer air drag
or backward_euler where spring damping matters.
Colliders act after the solve, as in position-based schemes: a particle deeper than the
collider's thickness is put back on the offset surface, its inward normal velocity removed,
and its tangential velocity reduced by mu times that normal velocity change (Coulomb),
relative to the collider's motion. Pinned particles follow x0 + h v0.
"""
import taichi as ti

from .. import runtime
from ..colliders import signed_distance
from ..forces import eval_attraction, eval_wind
from ..runtime import serial
from . import linalg
from .base import Integrator


@ti.data_oriented
class Projective(Integrator):
    """Liu et al. 2013 local/global solver. Options (defaults):

    iterations (10): local/global iterations per step.
    cg_tol (1e-3), cg_max_iterations (200): each global solve, warm-started from the
        previous iterate, stops at cg_tol times its starting residual. cg_max_iterations=10
        is about 4x cheaper and as accurate on the benchmark cloth, but leaves light stiff
        cloth jittering on colliders (docs/implicit.md).
    After each step ``stats`` holds iterations and cg_iterations (total).
    """
    name = "projective"
    defaults = {"iterations": 10, "cg_tol": 1e-3, "cg_max_iterations": 200}

    def __init__(self, model, **options):
        super().__init__(model, **options)
        # the model's fields, read by the kernels without being passed (Python launch time)
        self.mass, self.inv_mass, self.params = model.mass, model.inv_mass, model.params
        self.rest, self.ks, self.kd = model.spring_rest, model.spring_ks, model.spring_kd
        n, real = model.particle_count, runtime.real()
        self.y, self.x0, self.f_ext, self.b0 = (ti.Vector.field(3, real, shape=n)
                                                for _ in range(4))
        self.adj_start, self.adj = model.adjacency()
        # per adjacency entry: the matrix weight k_s + k_d/h and k_s l0 of its spring
        self.weight, self.k_rest = (ti.field(real, shape=self.adj.shape[0]) for _ in range(2))
        self.diag, self.precond = (ti.field(real, shape=n) for _ in range(2))
        self.solver = linalg.PCG(n, self.diag, self.weight, self.adj_start, self.adj,
                                 self.precond, model.inv_mass)
        self.stats = {}
        self._h = None

    def simulate(self, model, state_in, state_out, dt):
        h = dt
        if self._h != h:
            self._build_matrix(h)
            self._h = h
        self.f_ext.fill(0)
        if model.wind is not None:
            eval_wind(state_in.x, state_in.v, model.triangles, model.wind_params, state_in.t,
                      self.f_ext)
        if model.attraction is not None:
            eval_attraction(state_in.x, model.mass, *model.attraction, self.f_ext)
        self._predict(state_in.x, state_in.v, h)
        cg_total = 0
        for _ in range(self.options["iterations"]):
            self._local_global_rhs()
            iters, _ = self.solver.solve(self.options["cg_tol"],
                                         self.options["cg_max_iterations"], warm_start=True)
            cg_total += iters
        self._finish(1.0 / h, state_out.x, state_out.v)
        if model.collider_count:
            self._collide(state_out.x, state_out.v, model.inv_mass, model.collider_records,
                          model.collider_ranges, state_in.t + h, h)
        state_out.t = state_in.t + h
        self.stats = {"iterations": self.options["iterations"], "cg_iterations": cg_total}

    @ti.kernel
    def _predict(self, x: ti.template(), v: ti.template(), h: float):
        """y = x0 + h v0 + h^2 (g + f_ext / m) (pinned: x0 + h v0) and the constant part of
        the global right-hand side, b0 = M/h^2 y + c/h x0 + k_d/h L x0. The iterations
        start from x0 + h v0, so that a cloth at rest in equilibrium is a fixed point
        whatever the iteration count."""
        gravity = ti.Vector([self.params[0], self.params[1], self.params[2]])
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            self.x0[p] = x[p]
            self.solver.x[p] = x[p] + h * v[p]
            self.y[p] = x[p] + h * v[p]
            if self.inv_mass[p] > 0.0:
                self.y[p] += h * h * (gravity + self.inv_mass[p] * self.f_ext[p])
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            b = self.mass[p] / (h * h) * self.y[p] + self.params[3] / h * self.x0[p]
            for k in range(self.adj_start[p], self.adj_start[p + 1]):
                s, q = self.adj[k][0], self.adj[k][1]
                b += self.kd[s] / h * (self.x0[p] - self.x0[q])
            self.b0[p] = b

    @ti.kernel
    def _local_global_rhs(self):
        """Local step and global right-hand side in one gather: each spring's d_s, the
        nearest vector of rest length l0 (x_i - x_j) / |x_i - x_j|, seen from both ends,
        b = b0 + J d."""
        x = ti.static(self.solver.x)
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            b = self.b0[p]
            xp = x[p]
            for k in range(self.adj_start[p], self.adj_start[p + 1]):
                e = xp - x[self.adj[k][1]]
                b += self.k_rest[k] / ti.max(e.norm(), 1e-30) * e
            self.solver.b[p] = b

    @ti.kernel
    def _build_matrix(self, h: float):
        """The constant global matrix M/h^2 + c/h + sum_s (k_s + k_d/h) A_s A_s^T as
        per-particle diagonal and per-entry weights, and its inverse diagonal (Jacobi),
        built once per scene and dt."""
        ti.loop_config(serialize=ti.static(serial(self.diag)))
        for p in range(self.diag.shape[0]):
            self.diag[p] = self.mass[p] / (h * h) + self.params[3] / h
            total = self.diag[p]
            for k in range(self.adj_start[p], self.adj_start[p + 1]):
                s = self.adj[k][0]
                self.weight[k] = self.ks[s] + self.kd[s] / h
                self.k_rest[k] = self.ks[s] * self.rest[s]
                total += self.weight[k]
            self.precond[p] = 1.0 / total

    @ti.kernel
    def _finish(self, inv_h: float, x: ti.template(), v: ti.template()):
        """The step's positions and velocities (x - x0) / h."""
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            x[p] = self.solver.x[p]
            v[p] = (x[p] - self.x0[p]) * inv_h

    @ti.kernel
    def _collide(self, x: ti.template(), v: ti.template(), inv_mass: ti.template(),
                 records: ti.template(), ranges: ti.template(), t: float, h: float):
        """Project penetrating particles out; inelastic normal, Coulomb tangential."""
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            if inv_mass[p] > 0.0:
                for kind in ti.static(range(3)):
                    if ti.static(ranges[kind][1] > 0):
                        for c in range(ranges[kind][0], ranges[kind][0] + ranges[kind][1]):
                            rec = records[c]
                            phi, n = signed_distance(kind, rec, x[p], t)
                            depth = rec[18] - phi
                            if depth > 0.0:
                                x[p] += depth * n
                                vc = ti.Vector([rec[3], rec[4], rec[5]])
                                v_rel = v[p] - vc
                                vn = v_rel.dot(n)
                                if vn < 0.0:
                                    vt = v_rel - vn * n
                                    speed = vt.norm()
                                    cut = ti.min(rec[21] * (-vn), speed)
                                    vt -= cut * vt / ti.max(speed, 1e-30)
                                    v[p] = vc + vt
