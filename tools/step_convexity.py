"""Is a projective dynamics step a minimisation with one answer? The benchmark drape of
``bench_grad.py`` (an n x n cloth held at two corners over a sphere, mu 0.3) stepped at
--dt with --iterations of Liu's iterations (Anderson depth --anderson); at each step of
--at, the step's Jacobian J = dg/dx of its force residual g (``Projective.step_residual``)
at the iterate the iterations ended at, formed column by column by central differences of
--eps m, and the spectrum of its symmetric part relative to the inertia, M^-1/2 (-J_sym)
M^-1/2 h^2 (1 where the step is pure inertia; the springs' stiffness adds to it, a
compressed spring's transverse -k (l0 / l - 1) takes from it).

Where its smallest eigenvalue is below 0 the step's energy is not convex there: the
cloth can buckle within the step (wrinkle as it drapes), and Liu's iterations (a descent
with a constant, positive definite matrix) stall on those modes (measured: docs/grad.md,
Cost), so the step is not converged and the implicit function theorem's derivative,
which ``tcloth.grad`` gives for a converged step, is not the run's.

Prints ``convexity.<dt>.step<k>.<metric>: value`` lines: residual (the step's, relative
to its first iterate), smallest (the smallest eigenvalue above), negative (how many are
below 0), asymmetry (|J - J^T| / |J|, largest entries: the damping along the springs'
current directions).

Usage: python tools/step_convexity.py [--n 32] [--dt 0.016667] [--at 3]
                                      [--iterations 200] [--anderson 5] [--eps 1e-6]
"""
import argparse

import numpy as np

import tcloth
from bench_grad import cloth


def jacobian(integrator, x, free, eps):
    """dg/dx on the free particles' coordinates, by central differences."""
    rows = np.repeat(free, 3), np.tile(np.arange(3), len(free))
    columns = []
    for p, k in zip(*rows):
        step = np.zeros_like(x)
        step[p, k] = eps
        difference = integrator.step_residual(x + step) - integrator.step_residual(x - step)
        columns.append(difference[rows] / (2.0 * eps))
    return np.array(columns).T


def spectrum(sim, h, eps):
    """The metrics of the step just taken."""
    integrator = sim.integrator
    free = np.nonzero(sim.model.inv_mass.to_numpy() > 0)[0]
    jac = jacobian(integrator, sim.positions(), free, eps)
    inertia = np.repeat(sim.model.mass.to_numpy()[free], 3) / h ** 2
    scale = 1.0 / np.sqrt(inertia)
    relative = -0.5 * (jac + jac.T) * np.outer(scale, scale)
    eigenvalues = np.linalg.eigvalsh(relative)
    return {"residual": integrator.stats["residual"], "smallest": eigenvalues[0],
            "negative": int((eigenvalues < 0.0).sum()),
            "asymmetry": float(np.abs(jac - jac.T).max() / np.abs(jac).max())}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=32, help="the cloth's particles a side")
    parser.add_argument("--dt", type=float, default=1 / 60, help="the step, s")
    parser.add_argument("--at", default="3",
                        help="comma-separated steps (0 the first) whose Jacobian is formed")
    parser.add_argument("--iterations", type=int, default=200,
                        help="Liu's iterations a step")
    parser.add_argument("--anderson", type=int, default=5, help="Anderson depth, 0 off")
    parser.add_argument("--eps", type=float, default=1e-6,
                        help="the central differences' step, m")
    args = parser.parse_args()
    at = sorted({int(k) for k in args.at.split(",")})
    if at[0] < 0:
        parser.error(f"--at takes steps >= 0 (got {args.at!r})")
    tcloth.init(arch="cpu", precision="f64")
    sim = tcloth.Simulator(cloth(args.n), integrator="projective", dt=args.dt,
                           iterations=args.iterations, anderson=args.anderson)
    for step in range(at[-1] + 1):
        sim.step()
        if step in at:
            for name, value in spectrum(sim, args.dt, args.eps).items():
                print(f"convexity.{args.dt:g}.step{step}.{name}: {value:.4g}", flush=True)


if __name__ == "__main__":
    main()
