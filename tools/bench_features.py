"""Skip what is not needed: ms per symplectic Euler step (dt = 1/960) of the Warp benchmark
cloth (0.1 m spacing, 0.1 kg particles, k_s = 1000, k_d = 10) with each feature
added alone (flexion springs, a sphere, a plane, a box, wind, strain limiting) against
the bare cloth (structural + shear springs, gravity), all measured side by side in one
run, each configuration timed in --rounds interleaved rounds (medians). A feature that
is absent compiles out of the kernels and launches nothing (tests/test_simulator.py
counts the launches), so the bare cloth pays nothing for it.

Prints greppable lines ``features.<n>x<n>.<feature>.<ms_per_step|over_bare>: value``;
writes <out>/features.csv.

Usage: python tools/bench_features.py [--n 64] [--steps 100] [--rounds 5] [--out docs]
"""
import argparse
import os
import time

import numpy as np

import tcloth
from benchcsv import write_csv


def scene(n, feature):
    s = tcloth.Scene()
    s.add_cloth(resolution=(n, n), size=(0.1 * (n - 1),) * 2, center=(0.0, 1.0, 0.0),
                mass=0.1 * n * n, structural=(1000.0, 10.0), shear=(1000.0, 10.0),
                flexion=(1000.0, 10.0) if feature in ("flexion", "all") else None)
    if feature in ("sphere", "all"):
        s.add_sphere((0.0, 0.5, 0.0), 0.3)
    if feature in ("plane", "all"):
        s.add_plane((0.0, 0.0, 0.0), (0.0, 1.0, 0.0))
    if feature in ("box", "all"):
        s.add_box((0.5, 0.3, 0.0), (0.2, 0.2, 0.2))
    if feature in ("wind", "all"):
        s.set_wind((2.0, 0.0, 1.0), drag=1.0)
    if feature in ("strain_limiting", "all"):
        s.limit_strain(0.1, kinds=("structural",))
    return s


FEATURES = ["bare", "flexion", "sphere", "plane", "box", "wind", "strain_limiting", "all"]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=64)
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--out", default="docs")
    args = ap.parse_args(argv)
    tcloth.init()
    sims = {}
    for feature in FEATURES:
        sims[feature] = tcloth.Simulator(scene(args.n, feature), "symplectic_euler",
                                         dt=1 / 960)
        sims[feature].step(2)
    times = {feature: [] for feature in FEATURES}
    for _ in range(args.rounds):
        for feature, sim in sims.items():
            t0 = time.perf_counter()
            sim.step(args.steps)
            sim.state.x[0]
            times[feature].append((time.perf_counter() - t0) / args.steps)
    bare = np.median(times["bare"])
    rows = []
    for feature in FEATURES:
        ms = 1e3 * np.median(times[feature])
        rows.append({"n": args.n, "feature": feature, "ms_per_step": ms,
                     "over_bare": ms / (1e3 * bare)})
        key = f"features.{args.n}x{args.n}.{feature}"
        print(f"{key}.ms_per_step: {ms:.4g}")
        print(f"{key}.over_bare: {ms / (1e3 * bare):.3g}", flush=True)
    write_csv(os.path.join(args.out, "features.csv"), rows)


if __name__ == "__main__":
    main()
