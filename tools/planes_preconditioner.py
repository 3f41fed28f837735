"""Which preconditioner would projective dynamics' global solve need with the contact
planes in it (``integrators/contact_planes.py``)? The 64 x 64 fold of
``bench_self_collision.py`` (its saved state), projective at --dt with the planes, float64,
stepped --at steps; then each global solve of the next step is captured and solved again
here, in NumPy, by conjugate gradients to the solver's own tolerance (cg_tol of |b|), with
A applied by the solver's own product (``PCG.apply``: the springs, the colliders'
diagonal and the planes' couplings) and each preconditioner built from the vertex pairs
active at that iterate, each pair's direction u = (n on a, -n on b), U their columns:

  - ``vcycle``: the V-cycle the solver uses (``GridMultigrid.vcycle``), B r;
  - ``pair_blocks``: B r + sum over pairs of u (u.r) / (u.A u) (additive);
  - ``pair_space``: B r + Q r with Q = U (U^T A U)^+ U^T (additive);
  - ``two_level``: Q r + (I - Q A) B (I - A Q) r (a balancing two-level preconditioner:
    the pairs' subspace solved exactly, the V-cycle on what is left).

Prints ``preconditioner.<at>.<name>.iterations: k1,k2,...`` per solve (and ``.solver``,
what the solver itself took, ``.pairs``, the active pairs) and their medians; the measured
table is in docs/contact.md ("Which preconditioner, measured before building it"). The
solver has since got the two-level preconditioner (``integrators/deflation.py``), so its
``.solver`` iterations are now those of ``two_level`` (up to rounding and its start).

Usage: python tools/planes_preconditioner.py [--n 64] [--at 8,30] [--dt 0.016667]
"""
import argparse
import os

import numpy as np
import taichi as ti

import tcloth
from tcloth.testing.folding import fold_scene, folded_state, resample
from tcloth.app.script import load_script

HERE = os.path.dirname(os.path.abspath(__file__))


def conjugate_gradients(apply, b, precondition, tol, most=2000):
    """Iterations of preconditioned CG on A x = b from 0 until |r| < tol |b|."""
    x, r = np.zeros_like(b), b.copy()
    z = precondition(r)
    p, rz, stop = z.copy(), (r * z).sum(), tol * np.linalg.norm(b)
    for k in range(1, most + 1):
        ap = apply(p)
        alpha = rz / (p * ap).sum()
        x += alpha * p
        r -= alpha * ap
        if np.linalg.norm(r) < stop:
            return k
        z = precondition(r)
        rz, previous = (r * z).sum(), rz
        p = z + rz / previous * p
    return most


def preconditioners(apply, vcycle, pairs, normals, free):
    """The four preconditioners of the module docstring, from the active pairs."""
    n = len(free)
    columns = np.zeros((len(pairs), n, 3))
    for k, ((a, b), normal) in enumerate(zip(pairs, normals)):
        columns[k, a] += normal * free[a]
        columns[k, b] -= normal * free[b]
    a_columns = np.stack([apply(u) for u in columns])
    coarse = np.einsum("kpi,lpi->kl", columns, a_columns)
    inverse = np.linalg.pinv(coarse, rcond=1e-10, hermitian=True)

    def project(r):
        return np.einsum("k,kpi->pi", inverse @ np.einsum("kpi,pi->k", columns, r), columns)

    def pair_blocks(r):
        scale = np.einsum("kpi,pi->k", columns, r) / np.diag(coarse)
        return vcycle(r) + np.einsum("k,kpi->pi", scale, columns)

    def two_level(r):
        q = project(r)
        z = q + vcycle(r - apply(q))
        return z + project(r - apply(z))
    return {"vcycle": vcycle, "pair_blocks": pair_blocks,
            "pair_space": lambda r: vcycle(r) + project(r), "two_level": two_level}


def capture(n, at, dt):
    """Run the fold ``at`` steps, then solve each global solve of the next one again."""
    module = load_script(os.path.join(HERE, "..", "scenes", "fold.py"))[0]
    x40, v40 = folded_state(module, os.path.join(HERE, "data", "fold_40x40.npz"))
    scene = fold_scene(module, n)
    sim = tcloth.Simulator(scene, "projective", dt=dt)
    sim.set_state(positions=resample(x40, n), velocities=resample(v40, n))
    sim.step(at)
    integrator, solver = sim.integrator, sim.integrator.solver
    count = sim.model.particle_count
    free = sim.model.inv_mass.to_numpy() > 0
    v_in, out = (ti.Vector.field(3, ti.f64, shape=count) for _ in range(2))
    ny, nx = integrator.mg.shapes[0]

    def apply(v):
        v_in.from_numpy(v)
        solver.apply(v_in, out)
        return out.to_numpy() * free[:, None]

    def vcycle(r):
        return integrator.mg.vcycle(r.reshape(ny, nx, 3)).reshape(count, 3) * free[:, None]

    solve, found = solver.solve, {"solver": [], "pairs": []}

    def solve_twice(tol, most):
        b = solver.b.to_numpy() * free[:, None]
        rows = integrator.planes.rows
        k = int(rows.count[None])
        iterations, relative = solve(tol, most)
        found["solver"].append(iterations)
        found["pairs"].append(k)
        if k:
            for name, precondition in preconditioners(apply, vcycle, rows.pairs.to_numpy()[:k],
                                                      rows.n.to_numpy()[:k], free).items():
                found.setdefault(name, []).append(
                    conjugate_gradients(apply, b, precondition, tol))
        return iterations, relative
    solver.solve = solve_twice
    sim.step()
    return found


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=64)
    ap.add_argument("--at", default="8,30", help="steps before the captured one")
    ap.add_argument("--dt", type=float, default=1.0 / 60.0)
    args = ap.parse_args()
    if args.n < 8:
        ap.error(f"--n must be at least 8 (got {args.n})")
    tcloth.init("cpu", precision="f64")
    for at in (int(s) for s in args.at.split(",")):
        for name, values in capture(args.n, at, args.dt).items():
            what = name if name == "pairs" else name + ".iterations"
            print(f"preconditioner.{at}.{what}: {','.join(map(str, values))} "
                  f"(median {np.median(values):g})", flush=True)


if __name__ == "__main__":
    main()
