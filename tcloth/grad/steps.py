"""One step's adjoint, per integrator (``StepAdjoints``, which ``Trajectory`` inherits;
``adjoint.StepAdjoint`` gives the vector-Jacobian products of the step's kernel):

  - symplectic Euler, v1 = v + h M^-1 f(x, v), x1 = x + h v1: with a = v1_bar + h x1_bar
    (v1's whole adjoint) and the force's adjoint f_bar = h M^-1 a, x_bar = x1_bar + f_x^T
    f_bar and v_bar = a + f_v^T f_bar; the parameters get f_theta^T f_bar. Pinned particles
    (M^-1 = 0) move with their velocity;
  - backward Euler, x1 solving g(x1; x, v) = 0 (g the incremental potential's gradient),
    v1 = (x1 - x) / h: with r = x1_bar + v1_bar / h, the adjoint solve H lambda = r on the
    free particles, H = dg/dx1 the step's Hessian, solved by the integrator's own CG and
    preconditioner (multigrid on a single cloth grid) at the step's end (with
    self-collision, whose Hessian the integrator takes without the penalty's curvature
    and the closest points' motion: flexible GMRES on H's products by Taichi's reverse
    mode over g, preconditioned by that CG to PRECONDITIONER_TOL); then x_bar =
    -v1_bar / h - g_x^T lambda, v_bar = -g_v^T lambda, the parameters -g_theta^T lambda, and
    the pinned particles' share of -g_x1^T lambda (their x1 = x + h v) passed back to their
    x and v. This is the implicit function theorem's derivative of the converged step: the
    forward Newton must converge (``newton_tol``) well below the accuracy wanted of the
    gradient, and the adjoint CG (``adjoint_tol``) likewise (docs/grad.md measures both);
  - projective dynamics, x1 solving G(x1; x, v) = 0 (its force residual; the iterations'
    fixed point), v1 = F(x1; x, v) (the friction after the solve): F's vector-Jacobian
    product with v1_bar first, then the adjoint solve G_x1^T lambda = r (r = x1_bar plus
    F's share) on the free particles by flexible GMRES (``krylov.fgmres``; G_x1 is not
    symmetric: the springs' damping acts along their current direction), preconditioned
    by backward Euler's projected Hessian at the step's end (one V-cycle of its multigrid,
    or its block Jacobi off a grid: the same stiffness but for the damping's direction
    terms and friction), its products G_x1^T lambda by Taichi's reverse mode over G, at
    most 500 iterations; then x_bar, v_bar and the parameters as for backward Euler. The
    derivative of the converged step: the forward iterations (``iterations``) must bring
    the residual (``stats["residual"]``; the largest is ``Result.forward_residual``) well
    below the accuracy wanted.
"""
import numpy as np

from .. import runtime
from .krylov import fgmres

# the relative residual of the CG that preconditions backward Euler's adjoint solve with
# self-collision (its Hessian less the contacts' curvature: a few outer iterations)
PRECONDITIONER_TOL = 1e-3


class StepAdjoints:
    """One step's adjoint for each integrator (the module), on a ``Trajectory``'s
    attributes: adjoint (``StepAdjoint``), sim, pinned, free, adjoint_tol, _newton,
    _x_start, _rhs, _inv_mass, _mass_bar."""

    def _explicit_adjoint(self, x, v, x_bar, v_bar, h, m):
        a = v_bar + h * x_bar
        self.adjoint.set_inputs(x, v)
        gx, gv, _ = self.adjoint.vjp(h * self._inv_mass[:, None] * a, h, self.sim.time_at(m))
        if self._mass_bar is not None:      # v1's M^-1: d(h f / m)/dm = -h f / m^2 at fixed f
            f = self.adjoint.out.to_numpy().astype(np.float64)
            self._mass_bar -= h * self._inv_mass ** 2 * (a * f).sum(axis=1)
        return x_bar + gx, a + gv

    def _implicit_adjoint(self, x, v, x1, x_bar, v_bar, h, m):
        sim, adj = self.sim, self.adjoint
        integ = sim.integrator
        npr = runtime.numpy_real()
        t0 = sim.time_at(m)
        r = x_bar + v_bar / h
        r[self.pinned] = 0.0
        # the step's Hessian at its end, with its lagged quantities from its start
        adj.set_inputs(x, v, x1)
        if adj.self_contact:        # the stage's list at x, for the Hessian's contacts
            sim.contact.refresh(adj.x)
        integ.potential.begin(adj.x, adj.v, h, t0, self._x_start)
        integ.hessian.assemble(adj.x1, h, t0 + h)
        if adj.self_contact:
            adj.evaluate(h, t0 + h)         # g's values, for repeat_vjp
            lam, iters, residual = self._transposed_solve(r, h, integ.hessian, True)
        else:
            self._rhs.from_numpy((-r).astype(npr))      # solve(grad) solves H dx = -grad
            iters, residual = integ.hessian.solve(self._rhs, self.adjoint_tol, 100 * len(x))
            lam = integ.hessian.dx.to_numpy().astype(np.float64)
        lam[self.pinned] = 0.0
        gx, gv, gx1 = adj.vjp(-lam, h, t0 + h)
        x_new = -v_bar / h + gx
        v_new = gv.copy()
        carried = x_bar[self.pinned] + v_bar[self.pinned] / h + gx1[self.pinned]
        x_new[self.pinned] += carried
        v_new[self.pinned] += h * carried
        return x_new, v_new, int(iters), float(residual)

    def _projective_adjoint(self, x, v, x1, x_bar, v_bar, h, m):
        adj, pinned = self.adjoint, self.pinned
        t0 = self.sim.time_at(m)
        t1 = t0 + h
        adj.set_inputs(x, v, x1)
        newton = self._newton
        newton.potential.begin(adj.x, adj.v, h, t0, self._x_start)
        newton.hessian.assemble(adj.x1, h, t1)
        # v1 = F(x1; x, v), the friction after the solve
        x_new, v_new, gx1 = adj.vjp(v_bar, h, t1, friction=True)
        r = x_bar + gx1

        adj.evaluate(h, t1)                 # the residual's values, for repeat_vjp
        lam, iters, residual = self._transposed_solve(r, h, newton.hessian, False)
        gx, gv, gx1 = adj.vjp(-lam, h, t1)
        x_new = x_new + gx
        v_new = v_new + gv
        carried = r[pinned] + gx1[pinned]
        x_new[pinned] += carried
        v_new[pinned] += h * carried
        return x_new, v_new, int(iters), float(residual)

    def _transposed_solve(self, r, h, hessian, solve):
        """lambda solving J^T lambda = r on the free particles, J the adjoint kernel's
        Jacobian in x1 at its inputs (its values evaluated; the products by its reverse
        mode), by flexible GMRES preconditioned by backward Euler's ``hessian`` as
        assembled: by its CG to PRECONDITIONER_TOL (``solve``), else one V-cycle (or its
        block Jacobi). The parameters' gradients are left as they were. Returns (lambda,
        iterations, the relative residual)."""
        adj, free = self.adjoint, self.free
        npr = runtime.numpy_real()

        def transposed(z):
            seed = np.zeros_like(r)
            seed[free] = z.reshape(-1, 3)
            return adj.repeat_vjp(seed, h)[free].ravel()

        def precondition(z):
            b = np.zeros_like(r)
            b[free] = -z.reshape(-1, 3)
            self._rhs.from_numpy(b.astype(npr))
            if solve:                       # dx solving H dx = -b
                hessian.solve(self._rhs, PRECONDITIONER_TOL, 100 * len(r))
            else:                           # dx = -B b
                hessian.descent(self._rhs)
            return hessian.dx.to_numpy()[free].ravel().astype(np.float64)

        kept = adj.parameter_grads()        # the solve's products accumulate nothing
        lam_free, iters, residual = fgmres(transposed, precondition, r[free].ravel(),
                                           self.adjoint_tol, max_iterations=500)
        adj.set_parameter_grads(kept)
        lam = np.zeros_like(r)
        lam[free] = lam_free.reshape(-1, 3)
        return lam, iters, residual
