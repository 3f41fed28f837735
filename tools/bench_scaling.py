"""Scaling: substep time and particle updates per second of the explicit cloth step
(symplectic Euler, grid stencil, structural + shear + flexion springs, gravity, two
corners pinned) for n x n cloths from 32 x 32 to 1024 x 1024, float32 and float64, with
the memory each simulator takes (resident-set growth while it is built and first run,
per particle) and the cost per particle relative to 64 x 64.

Prints greppable lines ``scaling.<precision>.<n>x<n>.<metric>: value``; writes
<out>/scaling.csv and <out>/img/scaling.png (matplotlib).

Usage: python tools/bench_scaling.py [--sizes 32,64,128,256,512,1024] [--steps 50]
                                     [--arch cpu] [--out docs]
"""
import argparse
import os
import time

import numpy as np

import tcloth
from benchcsv import write_csv


def rss_bytes():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def cloth(n):
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(n, n), size=(0.1 * (n - 1),) * 2, mass=0.1 * n * n,
                    structural=(1000.0, 10.0), shear=(1000.0, 10.0), flexion=(1000.0, 10.0))
    return scene


def measure(n, steps, precision):
    scene = cloth(n)
    before = rss_bytes()
    sim = tcloth.Simulator(scene, "symplectic_euler", dt=1 / 960)
    sim.step(2)
    memory = rss_bytes() - before
    times = []
    for _ in range(steps):
        t0 = time.perf_counter()
        sim.step(1)
        sim.state.x[0]                      # synchronise
        times.append(time.perf_counter() - t0)
    ms = 1e3 * float(np.median(times))
    return {"precision": precision, "n": n, "particles": n * n, "springs": scene.num_springs,
            "ms_per_substep": ms, "particle_updates_per_s": n * n / (ms * 1e-3),
            "ns_per_particle": 1e6 * ms / (n * n), "bytes_per_particle": memory / (n * n)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="32,64,128,256,512,1024")
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--precisions", default="f32,f64")
    ap.add_argument("--arch", default="cpu")
    ap.add_argument("--out", default="docs")
    args = ap.parse_args(argv)
    rows = []
    for precision in args.precisions.split(","):
        tcloth.init(arch=args.arch, precision=precision)
        for n in (int(s) for s in args.sizes.split(",")):
            row = measure(n, args.steps, precision)
            rows.append(row)
            for metric in ("ms_per_substep", "particle_updates_per_s", "ns_per_particle",
                           "bytes_per_particle"):
                print(f"scaling.{precision}.{n}x{n}.{metric}: {row[metric]:.4g}", flush=True)
        base = next((r for r in rows if r["precision"] == precision and r["n"] == 64), None)
        if base is not None:
            worst = max(r["ns_per_particle"] for r in rows
                        if r["precision"] == precision and r["n"] >= 64)
            print(f"scaling.{precision}.per_particle_cost_max_over_64x64: "
                  f"{worst / base['ns_per_particle']:.2f}")
    os.makedirs(os.path.join(args.out, "img"), exist_ok=True)
    write_csv(os.path.join(args.out, f"scaling_{args.arch}.csv"), rows)
    _plot(rows, os.path.join(args.out, "img", f"scaling_{args.arch}.png"))


def _plot(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax_t, ax_p) = plt.subplots(1, 2, figsize=(11, 4))
    for precision in sorted({r["precision"] for r in rows}):
        pts = [r for r in rows if r["precision"] == precision]
        ax_t.plot([r["particles"] for r in pts], [r["ms_per_substep"] for r in pts], "o-",
                  label=precision)
        ax_p.plot([r["particles"] for r in pts], [r["ns_per_particle"] for r in pts], "o-",
                  label=precision)
    ax_t.set(xscale="log", yscale="log", xlabel="particles", ylabel="ms per substep")
    ax_p.set(xscale="log", xlabel="particles", ylabel="ns per particle per substep")
    ax_t.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    print(f"# wrote {path}")


if __name__ == "__main__":
    main()
