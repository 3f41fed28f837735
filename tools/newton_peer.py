"""The hanging cloth of tools/bench_realtime.py in Newton (``pip install newton``), for a
side-by-side run: its SolverVBD or SolverXPBD on the CPU.

Run with a Python that has newton (it needs numpy >= 2, so a venv of its own is
simplest); bench_realtime.py calls it with --newton-python and reads the .npz it writes.

The scene is tcloth's ``add_cloth(resolution=(n, n), size=(1, 1), plane="xy",
center=(0, 1, 0), mass=0.2)`` with the same springs (Newton's ``add_spring`` takes the
same k_s and an axial damping k_d in N s/m): particle (i, j) at x = i h - 0.5,
y = 1.5 - j h, index j n + i, the two top corners pinned (mass 0, not ACTIVE). No
triangle membrane or dihedral bending. SolverVBD needs a colouring of the spring graph
(``builder.color()`` reads triangles only): (i mod 3, j mod 3), nine colours, since no
spring offset is 0 mod 3 in both coordinates.

Usage: python tools/newton_peer.py --solver vbd|xpbd --n 128 --iterations 10
                                   --steps 60 --dt 0.0166667 --out result.npz
The first step is a warm-up (Warp compiles or loads its kernels) and is not timed.
"""
import argparse
import importlib.util
import json
import os
import time

import numpy as np

FAMILIES = {"structural": ([(1, 0), (0, 1)], 1000.0, 0.5),
            "shear": ([(1, 1), (-1, 1)], 100.0, 0.25),
            "flexion": ([(2, 0), (0, 2)], 10.0, 0.05)}


def numpy_reference(name):
    """The module tcloth/testing/NAME.py (one that imports NumPy alone: ``meshes``,
    ``crossings``), read from its file: the peers run in a Python with Newton and no tcloth,
    and importing the package would import Taichi."""
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tcloth", "testing",
                        f"{name}.py")
    spec = importlib.util.spec_from_file_location(f"tcloth_testing_{name}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def build(n, mass, device):
    import newton
    h = 1.0 / (n - 1)
    builder = newton.ModelBuilder(up_axis=newton.Axis.Y, gravity=(0.0, -9.81, 0.0))
    ii, jj = np.meshgrid(np.arange(n), np.arange(n))
    pos = np.stack([ii * h - 0.5, 1.5 - jj * h, np.zeros(ii.shape)], -1).reshape(-1, 3)
    pinned = np.zeros(n * n, dtype=bool)
    pinned[[0, n - 1]] = True
    active = int(newton.ParticleFlags.ACTIVE)
    builder.add_particles(pos.tolist(), [(0.0, 0.0, 0.0)] * (n * n),
                          mass=[0.0 if p else mass / (n * n) for p in pinned],
                          radius=[0.0] * (n * n), flags=[0 if p else active for p in pinned])
    add_grid_springs(builder, n, FAMILIES)
    return builder.finalize(device=device)


def add_grid_springs(builder, n, families):
    """The springs of an n x n grid whose particle (i, j) is builder particle j n + i:
    ``families`` maps a name to (offsets (di, dj), k_s, k_d); and the grid's colouring
    for SolverVBD, (i mod 3, j mod 3) (no spring offset of tcloth's families is 0 mod 3 in
    both coordinates)."""
    idx = np.arange(n * n).reshape(n, n)
    for offsets, ke, kd in families.values():
        for di, dj in offsets:
            for j in range(n):
                for i in range(n):
                    if 0 <= i + di < n and 0 <= j + dj < n:
                        builder.add_spring(int(idx[j, i]), int(idx[j + dj, i + di]), ke, kd,
                                           control=0.0)
    builder.set_coloring(grid_colouring(n)[0])


def grid_colouring(n):
    """(SolverVBD's nine colour groups, each particle's colour) of an n x n grid whose
    particle (i, j) is j n + i: (i mod 3, j mod 3)."""
    ii, jj = np.meshgrid(np.arange(n), np.arange(n))
    colours = ((ii % 3) + 3 * (jj % 3)).ravel()
    return [np.nonzero(colours == c)[0].astype(int) for c in range(9)], colours


def timed_steps(model, solver, steps, dt, record=None):
    """Run ``steps`` solver steps from the model's initial state: (final particle
    positions (N, 3) float64, wall times of all steps but the first, the warm-up in which
    Warp compiles or loads its kernels). ``record``, if given, is called with each step's
    particle positions (N, 3), untimed."""
    import warp as wp
    states = [model.state(), model.state()]
    control = model.control()
    times = []
    for k in range(steps):
        start = time.perf_counter()
        states[0].clear_forces()
        solver.step(states[0], states[1], control, None, dt)
        wp.synchronize_device(model.device)
        if k:
            times.append(time.perf_counter() - start)
        if record is not None:
            record(states[1].particle_q.numpy().copy())
        states.reverse()
    return states[0].particle_q.numpy().astype(np.float64), np.array(times)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--solver", choices=["vbd", "xpbd"], required=True)
    ap.add_argument("--n", type=int, default=128)
    ap.add_argument("--iterations", type=int, default=10)
    ap.add_argument("--steps", type=int, default=60)
    ap.add_argument("--dt", type=float, default=1.0 / 60.0)
    ap.add_argument("--mass", type=float, default=0.2)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    import warp as wp
    import newton
    wp.init()
    model = build(args.n, args.mass, args.device)
    solvers = {"vbd": newton.solvers.SolverVBD, "xpbd": newton.solvers.SolverXPBD}
    solver = solvers[args.solver](model, iterations=args.iterations)
    positions, times = timed_steps(model, solver, args.steps, args.dt)
    summary = {"newton": newton.__version__, "warp": wp.config.version,
               "solver": args.solver, "iterations": args.iterations}
    np.savez(args.out, positions=positions, step_times=times, summary=json.dumps(summary))


if __name__ == "__main__":
    main()
