"""Implicit solvers at one step per frame (dt = 1/60) on the Warp cloth benchmark's cloth
(0.1 m spacing, 0.1 kg per particle, two corners fixed) with every spring family at
k_s = --k and k_d = 10: ms per step and iteration counts (medians over --steps steps),
then total energy, CG iterations and ms per step over --energy-steps steps, and each
solver's distance from the default Newton run at their end. Prints greppable lines

    implicit_bench.<solver>.<n>x<n>.<metric>: value

and writes <out>/implicit_bench.csv, <out>/implicit_energy.csv and <out>/implicit_energy.png
(energy and ms per step, one line per solver; needs matplotlib).

Usage: python tools/bench_implicit.py [--sizes 32,64,128 ('' skips)] [--steps 7] [--k 1e4]
                                      [--energy-steps 120] [--out docs] [--arch cpu]
"""
import argparse
import os
import time

import numpy as np

import tcloth
from benchcsv import write_csv

SOLVERS = {
    "projective_10it": ("projective", {"iterations": 10}),              # multigrid
    "projective_10it_cg": ("projective", {"iterations": 10, "linear_solver": "cg"}),
    "backward_euler_1solve": ("backward_euler", {"newton_iterations": 1, "line_search": False,
                                                 "cg_tol": 1e-3}),           # multigrid
    "backward_euler_1solve_jacobi": ("backward_euler", {"newton_iterations": 1,
                                                        "line_search": False, "cg_tol": 1e-3,
                                                        "linear_solver": "cg"}),
    "backward_euler_newton": ("backward_euler", {}),                     # multigrid
    "backward_euler_newton_jacobi": ("backward_euler", {"linear_solver": "cg"}),
    "backward_euler_newton_projected": ("backward_euler", {"exact_hessian": False}),
}


def warp_cloth(n, k):
    """The cloth of warp.examples.benchmarks.benchmark_cloth (n x n, corners of row 0
    fixed) with all three spring families at stiffness k."""
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(n, n), size=(0.1 * (n - 1),) * 2,
                    center=(0.05 * (n - 1), 0.0, 0.05 * (n - 1)), mass=0.1 * n * n,
                    structural=(k, 10.0), shear=(k, 10.0), flexion=(k, 10.0))
    return scene


def speed(sizes, steps, k, out):
    rows = []
    for n in sizes:
        for label, (name, options) in SOLVERS.items():
            sim = tcloth.Simulator(warp_cloth(n, k), name, dt=1 / 60, **options)
            sim.step(2)                      # compiles both state orders
            times, stats = [], []
            for _ in range(steps):
                t0 = time.perf_counter()
                sim.step(1)
                times.append(time.perf_counter() - t0)
                stats.append(sim.integrator.stats)
            row = {"solver": label, "n": n, "ms_per_step": 1e3 * np.median(times)}
            for stat in stats[0]:
                if stat != "residual":
                    row[stat] = np.median([s[stat] for s in stats])
            row["max_strain"] = sim.max_strain()
            rows.append(row)
            key = f"implicit_bench.{label}.{n}x{n}"
            for metric, value in row.items():
                if metric not in ("solver", "n"):
                    print(f"{key}.{metric}: {value:.4g}", flush=True)
    write_csv(os.path.join(out, "implicit_bench.csv"), rows)


def energy_history(n, steps, k, out):
    """Energy, CG iterations and ms per step over ``steps`` steps for every solver, and
    each one's largest distance from the default Newton run at the end."""
    histories, final = {}, {}
    for label, (name, options) in SOLVERS.items():
        sim = tcloth.Simulator(warp_cloth(n, k), name, dt=1 / 60, **options)
        sim.step(2)                      # compiles both state orders, untimed
        sim.reset()
        energy, cg, ms, newton = [sim.energy()["total"]], [0], [0.0], [0]
        for _ in range(steps):
            t0 = time.perf_counter()
            sim.step(1)
            ms.append(1e3 * (time.perf_counter() - t0))
            energy.append(sim.energy()["total"])
            cg.append(sim.integrator.stats["cg_iterations"])
            newton.append(sim.integrator.stats.get("newton_iterations", 0))
        histories[label] = (np.array(energy), np.array(cg), np.array(ms))
        final[label] = sim.positions()
        rises = int(np.sum(np.diff(energy) > 1e-6 * abs(energy[0] - min(energy))))
        print(f"implicit_bench.{label}.{n}x{n}.energy_final: {energy[-1]:.6g}")
        print(f"implicit_bench.{label}.{n}x{n}.energy_rises: {rises}")
        print(f"implicit_bench.{label}.{n}x{n}.cg_per_step_median: {np.median(cg[1:]):.4g}")
        if name == "backward_euler":
            print(f"implicit_bench.{label}.{n}x{n}.newton_per_step_median: "
                  f"{np.median(newton[1:]):.4g}")
        for q in (10, 50, 90):
            print(f"implicit_bench.{label}.{n}x{n}.ms_per_step_p{q}: "
                  f"{np.percentile(ms[1:], q):.4g}", flush=True)
    for label, x in final.items():
        gap = np.abs(x - final["backward_euler_newton"]).max()
        print(f"implicit_bench.{label}.{n}x{n}.distance_from_newton_m: {gap:.4g}")
    rows = [{"step": s, "time": s / 60,
             **{f"{label}.{what}": h[i][s] for label, h in histories.items()
                for i, what in enumerate(("energy", "cg", "ms"))}}
            for s in range(steps + 1)]
    write_csv(os.path.join(out, "implicit_energy.csv"), rows)
    _plot(histories, n, k, os.path.join(out, "img", "implicit_energy.png"))


def _plot(histories, n, k, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax_e, ax_ms) = plt.subplots(1, 2, figsize=(11, 4))
    for label, (energy, _, ms) in histories.items():
        t = np.arange(len(energy)) / 60
        ax_e.plot(t, energy, label=label)
        ax_ms.plot(t[1:], ms[1:], label=label)
    ax_e.set(xlabel="time (s)", ylabel="total energy (J)",
             title=f"{n}x{n} cloth, k_s = {k:g}, dt = 1/60")
    ax_ms.set(xlabel="time (s)", ylabel="wall time per step (ms)", yscale="log",
              title="one thread of this machine")
    ax_e.legend(fontsize=8)
    fig.tight_layout()
    os.makedirs(os.path.dirname(path), exist_ok=True)
    fig.savefig(path, dpi=100)
    print(f"# wrote {path}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="32,64,128")
    ap.add_argument("--steps", type=int, default=7)
    ap.add_argument("--k", type=float, default=1e4)
    ap.add_argument("--energy-steps", type=int, default=120)
    ap.add_argument("--energy-size", type=int, default=128)
    ap.add_argument("--out", default="docs")
    ap.add_argument("--arch", default="cpu")
    args = ap.parse_args(argv)
    tcloth.init(arch=args.arch)
    os.makedirs(args.out, exist_ok=True)
    if args.sizes:
        speed([int(s) for s in args.sizes.split(",")], args.steps, args.k, args.out)
    if args.energy_steps:
        energy_history(args.energy_size, args.energy_steps, args.k, args.out)


if __name__ == "__main__":
    main()
