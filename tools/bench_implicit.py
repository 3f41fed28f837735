"""Implicit solvers on a hanging cloth at one step per frame (dt = 1/60): ms per step and
iteration counts, medians over the measured steps. Prints greppable lines

    implicit_bench.<solver>.<n>x<n>.<metric>: value

Usage: python tools/bench_implicit.py [--sizes 32,64] [--steps 5] [--k 1e4] [--arch cpu]
"""
import argparse
import time

import numpy as np

import tcloth

SOLVERS = {"projective_10it": ("projective", {"iterations": 10}),
           "backward_euler_1solve": ("backward_euler", {"newton_iterations": 1,
                                                        "line_search": False, "cg_tol": 1e-3}),
           "backward_euler_newton": ("backward_euler", {})}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="32,64")
    ap.add_argument("--steps", type=int, default=5)
    ap.add_argument("--k", type=float, default=1e4)
    ap.add_argument("--arch", default="cpu")
    args = ap.parse_args(argv)
    tcloth.init(arch=args.arch)
    for n in (int(s) for s in args.sizes.split(",")):
        for label, (name, options) in SOLVERS.items():
            scene = tcloth.Scene()
            scene.add_cloth(resolution=(n, n), size=(1.0, 1.0), structural=(args.k, 1.0),
                            shear=(args.k / 10, 0.5), flexion=(args.k / 100, 0.1))
            sim = tcloth.Simulator(scene, name, dt=1 / 60, **options)
            sim.step(1)
            times, stats = [], []
            for _ in range(args.steps):
                t0 = time.perf_counter()
                sim.step(1)
                times.append(time.perf_counter() - t0)
                stats.append(sim.integrator.stats)
            key = f"implicit_bench.{label}.{n}x{n}"
            print(f"{key}.ms_per_step: {1e3 * np.median(times):.1f}")
            for stat in stats[0]:
                if stat != "residual":
                    print(f"{key}.{stat}: {np.median([s[stat] for s in stats]):.0f}")
            print(f"{key}.max_strain: {sim.max_strain():.4f}", flush=True)


if __name__ == "__main__":
    main()
