"""Projective dynamics for mass-spring systems: the local/global solver of Liu, Bargteil,
O'Brien & Kavan 2013, "Fast Simulation of Mass-Spring Systems".

A backward Euler step minimises 1/(2h^2) |x - y|_M^2 + sum_s k_s/2 |x_i - x_j - d_s|^2
over positions x and spring directions d_s with |d_s| = l0_s, alternating
  local:  d_s = l0_s (x_i - x_j) / |x_i - x_j|            (every spring in parallel)
  global: (M/h^2 + c/h + L) x = M/h^2 y + c/h x0 + J d     (one constant matrix)
with y = x0 + h v0 + h^2 M^-1 f_ext: gravity, wind and attraction enter explicitly at the
start of the step, air drag c implicitly. L = sum_s k_s A_s A_s^T is constant, so its
block-Jacobi preconditioner is built once per scene; each global solve is warm-started CG.
Spring damping k_d enters as the constant Laplacian term k_d/h A_s A_s^T (damping of the
relative velocity of the two ends in all directions, a documented simplification of the
axial damping of the explicit integrators, which keeps the matrix constant).
Colliders act after the solve, as in position-based schemes: a particle deeper than the
collider's thickness is put back on the offset surface, its inward normal velocity removed,
and its tangential velocity reduced by mu times that normal velocity change (Coulomb),
relative to the collider's motion. Pinned particles follow x0 + h v0.
"""
import taichi as ti

from .. import runtime
from ..colliders import signed_distance
from ..forces import eval_attraction, eval_wind
from . import linalg
from .base import Integrator


@ti.data_oriented
class Projective(Integrator):
    """Liu et al. 2013 local/global solver. Options (defaults):

    iterations (10): local/global iterations per step.
    cg_tol (1e-6), cg_max_iterations (200): each global solve.
    After each step ``stats`` holds iterations and cg_iterations (total).
    """
    name = "projective"
    defaults = {"iterations": 10, "cg_tol": 1e-6, "cg_max_iterations": 200}

    def __init__(self, model, **options):
        super().__init__(model, **options)
        n, real = model.particle_count, runtime.real()
        self.y, self.x0, self.x_start, self.rhs, self.f_ext = (
            ti.Vector.field(3, real, shape=n) for _ in range(5))
        self.d = ti.Vector.field(3, real, shape=max(model.spring_count, 1))
        self.precond = ti.Matrix.field(3, 3, real, shape=n)
        self.work = linalg.Work(n)
        self.stats = {}
        self._h = None

    def simulate(self, model, state_in, state_out, dt):
        h = dt
        if self._h != h:
            self._build_preconditioner(model.mass, model.params, model.spring_pairs,
                                       model.spring_ks, model.spring_kd, model.spring_count, h)
            self._h = h
        self.f_ext.fill(0)
        if model.wind is not None:
            eval_wind(state_in.x, state_in.v, model.triangles, model.wind_params, state_in.t,
                      self.f_ext)
        if model.attraction is not None:
            eval_attraction(state_in.x, model.mass, *model.attraction, self.f_ext)
        self._predict(state_in.x, state_in.v, model.mass, model.inv_mass, model.params, h)
        x = state_out.x
        x.copy_from(self.x_start)
        cg_total = 0

        def matvec(p, out):
            self._matvec(model.mass, model.params, model.spring_pairs, model.spring_ks,
                         model.spring_kd, model.spring_count, h, p, out)

        for _ in range(self.options["iterations"]):
            if model.spring_count:
                self._local(x, model.spring_pairs, model.spring_rest, model.spring_count)
            self._global_rhs(model.mass, model.params, model.spring_pairs, model.spring_ks,
                             model.spring_kd, model.spring_count, h)
            iters, _ = linalg.pcg(matvec, self.precond, model.inv_mass, self.rhs, x, self.work,
                                  self.options["cg_tol"], self.options["cg_max_iterations"],
                                  warm_start=True)
            cg_total += iters
        self._velocities(x, 1.0 / h, state_out.v)
        if model.collider_count:
            self._collide(x, state_out.v, model.inv_mass, model.collider_records,
                          model.collider_ranges, state_in.t + h, h)
        state_out.t = state_in.t + h
        self.stats = {"iterations": self.options["iterations"], "cg_iterations": cg_total}

    @ti.kernel
    def _predict(self, x: ti.template(), v: ti.template(), mass: ti.template(),
                 inv_mass: ti.template(), params: ti.template(), h: float):
        """y = x0 + h v0 + h^2 (g + f_ext / m); pinned: x0 + h v0. The iterations start
        from x0 + h v0, so that a cloth at rest in equilibrium is a fixed point whatever
        the iteration count."""
        gravity = ti.Vector([params[0], params[1], params[2]])
        for p in range(x.shape[0]):
            self.x0[p] = x[p]
            self.x_start[p] = x[p] + h * v[p]
            self.y[p] = x[p] + h * v[p]
            if inv_mass[p] > 0.0:
                self.y[p] += h * h * (gravity + inv_mass[p] * self.f_ext[p])

    @ti.kernel
    def _local(self, x: ti.template(), pairs: ti.template(), rest: ti.template(),
               count: ti.i32):
        """d_s = l0 (x_i - x_j) / |x_i - x_j|: the nearest vector of rest length."""
        for s in range(count):
            e = x[pairs[s][0]] - x[pairs[s][1]]
            self.d[s] = rest[s] * e / ti.max(e.norm(), 1e-30)

    @ti.kernel
    def _global_rhs(self, mass: ti.template(), params: ti.template(), pairs: ti.template(),
                    ks: ti.template(), kd: ti.template(), count: ti.i32, h: float):
        """M/h^2 y + c/h x0 + J d + k_d/h (Laplacian x0)."""
        for p in range(self.rhs.shape[0]):
            self.rhs[p] = mass[p] / (h * h) * self.y[p] + params[3] / h * self.x0[p]
        for s in range(count):
            i, j = pairs[s][0], pairs[s][1]
            b = ks[s] * self.d[s] + kd[s] / h * (self.x0[i] - self.x0[j])
            self.rhs[i] += b
            self.rhs[j] -= b

    @ti.kernel
    def _matvec(self, mass: ti.template(), params: ti.template(), pairs: ti.template(),
                ks: ti.template(), kd: ti.template(), count: ti.i32, h: float,
                p_in: ti.template(), out: ti.template()):
        """(M/h^2 + c/h + sum_s (k_s + k_d/h) A_s A_s^T) p."""
        for p in range(out.shape[0]):
            out[p] = (mass[p] / (h * h) + params[3] / h) * p_in[p]
        for s in range(count):
            i, j = pairs[s][0], pairs[s][1]
            y = (ks[s] + kd[s] / h) * (p_in[i] - p_in[j])
            out[i] += y
            out[j] -= y

    @ti.kernel
    def _build_preconditioner(self, mass: ti.template(), params: ti.template(),
                              pairs: ti.template(), ks: ti.template(), kd: ti.template(),
                              count: ti.i32, h: float):
        """Inverse diagonal of the constant global matrix (built once per scene and dt)."""
        for p in range(self.precond.shape[0]):
            self.precond[p] = (mass[p] / (h * h) + params[3] / h) * ti.Matrix.identity(float, 3)
        for s in range(count):
            w = (ks[s] + kd[s] / h) * ti.Matrix.identity(float, 3)
            self.precond[pairs[s][0]] += w
            self.precond[pairs[s][1]] += w
        for p in range(self.precond.shape[0]):
            self.precond[p] = self.precond[p].inverse()

    @ti.kernel
    def _velocities(self, x: ti.template(), inv_h: float, v: ti.template()):
        for p in range(x.shape[0]):
            v[p] = (x[p] - self.x0[p]) * inv_h

    @ti.kernel
    def _collide(self, x: ti.template(), v: ti.template(), inv_mass: ti.template(),
                 records: ti.template(), ranges: ti.template(), t: float, h: float):
        """Project penetrating particles out; inelastic normal, Coulomb tangential."""
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
