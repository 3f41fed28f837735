"""Real-time solvers side by side: the hanging n x n cloth at one step per frame.

The cloth (1 m, 0.2 kg, pinned at its top corners, released flat; structural k_s 1000,
shear 100, flexion 10 N/m with damping) for ``--seconds`` at dt = 1/60 with VBD and XPBD
at each iteration count given, projective (10 iterations) and backward Euler (its
defaults), all in one run: the median wall time of a step (after a warm-up that
compiles, from the same start), and the error: the largest distance at the end from
backward Euler solved tightly (newton_tol 1e-7, cg_tol 1e-8), the solution VBD descends
to. With --newton-python (a Python with ``pip install newton``), Newton's SolverVBD and
SolverXPBD on the CPU run the same cloth (tools/newton_peer.py) at the same iteration
counts.

Lines: ``realtime.<n>.<solver>[.<iterations>].{ms_per_step,error_m,max_strain}``.

Usage: python tools/bench_realtime.py [--n 128] [--seconds 1] [--vbd 5,10,20,40]
                                      [--xpbd 10,40] [--unbatched] [--newton-python PATH]
                                      [--arch cpu]
"""
import argparse
import json
import os
import subprocess
import tempfile
import time

import numpy as np

import tcloth

HERE = os.path.dirname(os.path.abspath(__file__))
DT = 1.0 / 60.0


def hanging(n):
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0))
    scene.add_cloth(resolution=(n, n), size=(1.0, 1.0), plane="xy", center=(0.0, 1.0, 0.0),
                    mass=0.2, structural=(1000.0, 0.5), shear=(100.0, 0.25),
                    flexion=(10.0, 0.05))
    return scene


def strain(x, n):
    """The largest structural strain of an n x n grid's positions (N,3)."""
    g = x.reshape(n, n, 3)
    lengths = np.concatenate([np.linalg.norm(g[:, 1:] - g[:, :-1], axis=-1).ravel(),
                              np.linalg.norm(g[1:] - g[:-1], axis=-1).ravel()])
    return float(lengths.max() * (n - 1) - 1.0)


def run(n, steps, integrator, **options):
    """(positions at the end, median seconds a step). The instability test is off: the
    study measures how far an unconverged solver strays (VBD and XPBD at few iterations
    tear this cloth, which the test would stop)."""
    sim = tcloth.Simulator(hanging(n), integrator, dt=DT, energy_bound=False,
                           strain_bound=None, **options)
    start = sim.positions(), sim.velocities()
    sim.step(2)
    sim.set_state(*start)
    times = []
    for _ in range(steps):
        t = time.perf_counter()
        sim.step()
        sim.positions()
        times.append(time.perf_counter() - t)
    return sim.positions().astype(np.float64), float(np.median(times))


def newton_run(python, n, steps, solver, iterations):
    with tempfile.TemporaryDirectory() as folder:
        out = os.path.join(folder, "peer.npz")
        subprocess.run([python, os.path.join(HERE, "newton_peer.py"), "--solver", solver,
                        "--n", str(n), "--iterations", str(iterations), "--steps",
                        str(steps), "--dt", repr(DT), "--out", out], check=True,
                        stdout=subprocess.DEVNULL)
        data = np.load(out)
        return (data["positions"], float(np.median(data["step_times"])),
                json.loads(str(data["summary"])))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=128)
    ap.add_argument("--seconds", type=float, default=1.0)
    ap.add_argument("--vbd", default="5,10,20,40")
    ap.add_argument("--xpbd", default="10,40")
    ap.add_argument("--unbatched", action="store_true",
                    help="also VBD and XPBD with batch=False (a launch per kernel), side by "
                         "side with their batches (which run where the cloth is small)")
    ap.add_argument("--newton-python", default=None)
    ap.add_argument("--arch", default="cpu")
    args = ap.parse_args(argv)
    tcloth.init(arch=args.arch)
    n, steps = args.n, int(round(args.seconds / DT))
    reference, _ = run(n, steps, "backward_euler", newton_tol=1e-7, cg_tol=1e-8,
                       newton_iterations=40)

    def report(name, x, seconds):
        ok = bool(np.all(np.isfinite(x)))
        error = float(np.abs(x - reference).max()) if ok else float("nan")
        print(f"realtime.{n}.{name}.ms_per_step: {1e3 * seconds:.2f}")
        print(f"realtime.{n}.{name}.error_m: {error:.4g}")
        print(f"realtime.{n}.{name}.max_strain: {strain(x, n) if ok else float('nan'):.4g}",
              flush=True)
    for integrator in ("backward_euler", "projective"):
        report(integrator, *run(n, steps, integrator))
    for solver in ("vbd", "xpbd"):
        for iterations in (int(k) for k in getattr(args, solver).split(",") if k):
            report(f"{solver}.{iterations}", *run(n, steps, solver, iterations=iterations))
            if args.unbatched:
                report(f"{solver}.{iterations}.unbatched",
                       *run(n, steps, solver, batch=False, iterations=iterations))
    if args.newton_python:
        for solver, counts in (("vbd", args.vbd), ("xpbd", args.xpbd)):
            for iterations in (int(k) for k in counts.split(",") if k):
                x, seconds, summary = newton_run(args.newton_python, n, steps, solver,
                                                 iterations)
                report(f"newton_{solver}.{iterations}", x, seconds)
        print(f"realtime.newton_version: {summary['newton']} (warp {summary['warp']})")


if __name__ == "__main__":
    main()
