"""Backward Euler (Baraff & Witkin 1998), solved as a minimisation with Newton's method.

One step of size h finds the end positions x (and v = (x - x0) / h) that minimise the
incremental potential E(x) (``potential.py``): inertia, the potential terms (springs,
gravity, collider penalties, with spring damping, air drag, contact damping and Coulomb
friction as dissipation potentials with directions frozen at the step's start) and the
lagged terms (wind, attraction) as a constant force. grad E = 0 is backward Euler.

Newton's method: each Newton step solves H dx = -grad E by conjugate gradients on the
terms' 3 x 3 Hessian blocks (``hessian.py``: block Jacobi, or a multigrid V-cycle on a
single cloth grid), filtered so that pinned particles do not move; a backtracking line
search on E makes every iteration decrease E (or change it by less than its rounding
error), so a step never gains energy.

Compressed springs make H indefinite: their transverse stiffness k (1 - l0/|x_ij|) is
negative. The definiteness fix clamps it at 0 (the projected H, positive definite). With
the line search (the default) CG multiplies by the exact H instead, preconditioned by
the projected one, and stops at the first direction of non-positive curvature with a
descent direction (truncated Newton-CG, ``linalg.ConjugateGradients``). The step's
solution is a minimum of E, where the exact H is positive semi-definite, so Newton
converges quadratically there; on the projected H only linearly once the cloth folds.
``newton_iterations=1, line_search=False`` is Baraff & Witkin's single linearised solve,
on the projected H: a full step along a truncated direction could gain energy without
bound.
"""
import warnings

import numpy as np
import taichi as ti

from .. import runtime
from ..errors import ConvergenceWarning, SceneError
from ..runtime import serial
from . import hessian, linalg
from .base import Integrator
from .multigrid import single_grid
from .potential import IncrementalPotential

MIN_STEP = 2.0 ** -20       # the line search's smallest step along a direction


@ti.kernel
def _velocities(x0: ti.template(), x: ti.template(), inv_h: float, v_out: ti.template()):
    """v = (x - x0) / h; pinned particles keep v0 since their x = x0 + h v0."""
    ti.loop_config(serialize=ti.static(serial(x)))
    for p in range(x.shape[0]):
        v_out[p] = (x[p] - x0[p]) * inv_h


class BackwardEuler(Integrator):
    """Implicit Euler by Newton + preconditioned CG. Options (defaults):

    newton_iterations (20): the most Newton iterations a step may take (a cap: a step
        stops when it has converged, after 2-4 iterations on the benchmarks' cloths).
    newton_tol (1e-4): converged when a full Newton step would change no velocity by
        more than newton_tol * (1 m/s + max |v0|), or would move no particle by more than
        8 ulps of the largest coordinate (the positions' own rounding; in float32 at
        small dt that is the larger).
    cg_tol (1e-2): CG stops at this residual relative to the right-hand side (an inexact
        Newton step: the converged result is set by newton_tol; docs/implicit.md).
    cg_max_iterations (500).
    line_search (True): backtracking on E (Armijo); False takes full Newton steps.
    exact_hessian (None: the same as line_search): CG on the exact Hessian, stopped at
        negative curvature and preconditioned by the projected one (needs the line
        search), or on the projected Hessian (the definiteness fix).
    linear_solver ("auto"): the CG preconditioner, "multigrid" (only for a scene that is a
        single cloth grid) or "cg" (block Jacobi). "auto" takes the multigrid for a
        single cloth grid and block Jacobi otherwise (measurements in docs/implicit.md);
        with self-collision block Jacobi, whose CG takes the contacts' couplings.

    After each step ``stats`` holds newton_iterations, cg_iterations (total), residual
    (the last CG relative residual), converged, fallbacks (iterations whose Newton
    direction lowered E by no step, replaced by the preconditioned gradient) and potential
    (E at the start and after each accepted iterate: it never rises by more than its
    rounding error), and hold (None, or the iterations and E of a second Newton solve
    where the step ended below a mesh collider's planes, with them as a penalty in E:
    ``contact/hold.py``). A step that reaches the cap unconverged keeps the iterate with the
    lowest E found, adds one to ``unconverged`` and, the first time, warns
    (``tcloth.ConvergenceWarning``): it is not the backward Euler step, and may gain
    energy. With ``newton_iterations=1`` (Baraff & Witkin's single solve) nothing is
    counted.
    """
    name = "backward_euler"
    defaults = {"newton_iterations": 20, "newton_tol": 1e-4, "cg_tol": 1e-2,
                "cg_max_iterations": 500, "line_search": True, "linear_solver": "auto",
                "exact_hessian": None}
    live_options = frozenset({"newton_iterations", "newton_tol", "cg_tol", "cg_max_iterations"})

    def __init__(self, model, contact=None, **options):
        super().__init__(model, contact, **options)
        exact = self.options["exact_hessian"]
        line_search = self.options["line_search"]
        if exact not in (None, True, False):
            raise SceneError(f"exact_hessian must be None, True or False (got {exact!r})")
        if exact and not line_search:
            raise SceneError("exact_hessian=True needs line_search=True: without it a step "
                             "along a direction of negative curvature can gain energy")
        self.exact = line_search if exact is None else exact
        solver = self.options["linear_solver"]
        if model.self_collision is not None and solver != "cg":
            if solver == "multigrid":
                raise SceneError("linear_solver='multigrid' cannot take self-collision's "
                                 "couplings: use 'cg' (or 'auto')")
            solver = "cg"
        self.grid = single_grid(model, solver)
        self.potential = IncrementalPotential(model, contact, exact=self.exact)
        self.hessian = hessian.make(model, self.potential, self.exact, self.grid)
        self.x_try = ti.Vector.field(3, model.mass.dtype, shape=model.particle_count)
        # mesh colliders: the stage's planes as a penalty after the solve (``hold.py``)
        self.holds = self.potential.hold is not None
        self.stats = {}
        self.unconverged = 0
        self._eps = float(np.finfo(runtime.numpy_real()).eps)

    def simulate(self, model, state_in, state_out, dt):
        h, t1 = dt, state_in.t + dt
        opt = self.options
        x, e = state_out.x, self.potential
        e.begin(state_in.x, state_in.v, h, state_in.t, x)
        self._fallbacks = 0
        # a full Newton step below this is converged: newton_tol of the velocities, or
        # the positions' own rounding (in float32 at dt = 1e-4 that is 6e-4 m/s)
        tol = max(opt["newton_tol"] * h * (1.0 + linalg.max_norm(state_in.v)),
                  8.0 * self._eps * linalg.max_norm(state_in.x))
        it, cg_total, residual, converged, energies = self._newton(x, h, t1, tol)
        hold_run = None
        if self.holds and self.contact.begin_hold(state_in.x, x, state_in.t, h):
            # the mesh colliders' planes the step ends below, as a penalty in E
            # (``contact/hold.py``): Newton again on the new E
            hold_run = self._newton(x, h, t1, tol)
            self.contact.end_hold()
            cg_total += hold_run[1]
            residual, converged = hold_run[2], hold_run[3]
        _velocities(e.x0, x, 1.0 / h, state_out.v)
        state_out.t = t1
        self.stats = {"newton_iterations": it, "cg_iterations": cg_total, "residual": residual,
                      "converged": converged, "fallbacks": self._fallbacks,
                      "potential": energies,
                      "hold": None if hold_run is None else {
                          "newton_iterations": hold_run[0], "potential": hold_run[4]}}
        if not converged and opt["newton_iterations"] > 1:
            self.unconverged += 1
            if self.unconverged == 1:
                warnings.warn(
                    f"backward Euler stopped after "
                    f"{it if hold_run is None else hold_run[0]} Newton "
                    f"iterations{'' if hold_run is None else ' (of the hold)'} without converging "
                    f"(t = {t1:.6g} s, dt = {h:.3g} s): the step keeps the iterate with the "
                    f"lowest incremental potential found. Give newton_iterations > "
                    f"{opt['newton_iterations']} or a smaller dt; the integrator's "
                    f"'unconverged' counts such steps (reported once per simulator)",
                    ConvergenceWarning, stacklevel=4)

    def _newton(self, x, h, t1, tol):
        """Newton's iterations on E from the iterate x (in place) until converged or
        ``newton_iterations``. Returns (iterations, CG iterations, the last CG residual,
        converged, E at the start and after each accepted iterate)."""
        opt, e = self.options, self.potential
        cg_total, residual, it, converged = 0, 0.0, 0, False
        energy = e.evaluate(x, h, t1, True)[0]
        energies = [energy]
        for it in range(1, opt["newton_iterations"] + 1):
            self.hessian.assemble(x, h, t1, coarse=it == 1)
            iters, residual = self.hessian.solve(e.grad, opt["cg_tol"],
                                                 opt["cg_max_iterations"])
            cg_total += iters
            converged = linalg.max_norm(self.hessian.dx) < tol
            alpha = 1.0
            if opt["line_search"]:
                alpha, energy = self._search(x, h, t1, energy, not converged)
                if alpha == 0.0:
                    break           # nothing lowers E: x is the lowest found (and a step
                energies.append(energy)     # below tol is converged whether taken or not)
            linalg.axpy_into(x, x, alpha, self.hessian.dx)      # = x_try, bit for bit
            if converged:
                break
            if not opt["line_search"]:
                energy = e.evaluate(x, h, t1, True)[0]
        return it, cg_total, residual, converged, energies

    def _search(self, x, h, t, energy, fallback):
        """The line search along the Newton direction; where no step lowers E (a truncated
        CG iterate can be huge, and its steps too small to find), along the
        preconditioned gradient (``hessian.descent``) instead, a descent direction of the
        Hessian's own scale. Leaves ``hessian.dx`` the direction taken and
        ``potential.grad`` the gradient at x + alpha dx. Returns (alpha, E there); alpha
        0: neither lowered E. ``fallback`` False: the Newton direction only (a converged
        step, below the positions' resolution)."""
        alpha, trial = self.line_search(x, h, t, energy)
        if alpha > 0.0 or not fallback:
            return alpha, trial
        self._fallbacks += 1
        self.potential.evaluate(x, h, t, True)
        self.hessian.descent(self.potential.grad)
        return self.line_search(x, h, t, energy)

    def line_search(self, x, h, t, energy):
        """Backtracking from alpha = 1 along ``hessian.dx`` until E falls by the Armijo
        fraction 1e-4 of the slope, or by less than E's rounding error (near convergence
        the decrease is below it, and the test would compare rounding). Returns (alpha, E
        at x + alpha dx), with ``potential.grad`` the gradient there; (0, E) when no
        alpha >= MIN_STEP lowers E: E never rises across an accepted iterate by more
        than its rounding error."""
        dx = self.hessian.dx
        # an ascent direction (a rounding-level slope at convergence) may still take a
        # step that changes E by rounding only, never more
        slope = min(linalg.dot(self.potential.grad, dx), 0.0)
        alpha = 1.0
        while alpha >= MIN_STEP:
            linalg.axpy_into(self.x_try, x, alpha, dx)
            trial, rounding = self.potential.evaluate(self.x_try, h, t, True)
            if trial <= energy + 1e-4 * alpha * slope + rounding:
                return alpha, trial
            alpha *= 0.5
        return 0.0, energy
    def hessian_product(self, x, p, h, t=0.0):
        """H p at positions x (fields) within the step begun last; for tests and tools.
        Returns (N,3) NumPy."""
        self.hessian.assemble(x, h, t)
        return self.hessian.product(p)
