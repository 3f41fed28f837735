"""Work-precision: for each integrator and a range of dt, the error at a fixed final time
against a reference (RK4 at a much smaller dt, float64) versus wall time, on a cloth
falling from horizontal and swinging from two corners, at two stiffnesses, and on a cloth
falling onto a sphere. Measured convergence
orders (least-squares slope of log error against log dt over the runs below 10 % error)
go into the legend, and the cheapest method at a few error levels is printed.

Error: RMS over particles of |x - x_ref| at t = --time, m. Wall time: the run alone
(each simulator is compiled by two untimed first steps and reset).

Prints greppable lines ``accuracy.<scene>.<integrator>.<metric>: value``; writes
<out>/accuracy.csv and <out>/img/accuracy_<scene>.png (matplotlib).

Usage: python tools/bench_accuracy.py [--time 0.5] [--out docs]
"""
import argparse
import os
import time

import numpy as np

import tcloth
from benchcsv import write_csv

# label -> (integrator, options); backward Euler also with its Newton and CG tolerances
# tightened, so that its own time-discretisation error shows (the defaults stop Newton at
# a velocity change of 1e-4 m/s, an error floor)
METHODS = {"forward_euler": ("forward_euler", {}),
           "symplectic_euler": ("symplectic_euler", {}),
           "verlet": ("verlet", {}),
           "rk4": ("rk4", {}),
           "backward_euler": ("backward_euler", {}),
           "backward_euler_tight": ("backward_euler", {"newton_tol": 1e-9, "cg_tol": 1e-8}),
           "projective": ("projective", {})}
STEPS = [25, 50, 100, 200, 400, 800, 1600, 3200]
REFERENCE_STEPS = 25600


def swinging(k):
    def build():
        s = tcloth.Scene()
        s.add_cloth(resolution=(12, 12), size=(0.5, 0.5), plane="xz", mass=0.2,
                    structural=(k, 0.01 * k ** 0.5), shear=(k / 5, 0.005 * k ** 0.5),
                    flexion=(k / 20, 0.002 * k ** 0.5))
        return s
    return build


def on_sphere():
    s = tcloth.Scene()
    s.add_cloth(resolution=(12, 12), size=(0.6, 0.6), center=(0.0, 0.35, 0.0), mass=0.2,
                pinned=[], structural=(300.0, 0.2), shear=(60.0, 0.1), flexion=(15.0, 0.02))
    s.add_sphere((0.0, 0.0, 0.0), 0.2, friction=0.3, thickness=0.01, stiffness=3e3)
    return s


SCENES = {"swinging_k300": swinging(300.0), "swinging_k3000": swinging(3000.0),
          "cloth_on_sphere": on_sphere}


def run(sim, dt, steps):
    sim.reset(dt)
    t0 = time.perf_counter()
    try:
        sim.step(steps)
    except tcloth.InstabilityError:
        return None, time.perf_counter() - t0
    return sim.positions(), time.perf_counter() - t0


def order(points):
    """Slope of log error against log dt over the points below 10 % error."""
    pts = [(dt, err) for dt, err, _ in points if err is not None and 0 < err < 0.1 * 0.5]
    if len(pts) < 2:
        return float("nan")
    dt, err = np.log(np.array(pts)).T
    return float(np.polyfit(dt, err, 1)[0])


def study(name, build, final_time):
    scene = build()
    reference = tcloth.Simulator(scene, "rk4", dt=final_time / REFERENCE_STEPS)
    reference.step(REFERENCE_STEPS)
    x_ref = reference.positions()
    results, rows = {}, []
    for integrator, (kind, options) in METHODS.items():
        sim = tcloth.Simulator(scene, kind, dt=final_time / STEPS[-1], **options)
        sim.step(2)                              # compiles both state orders
        points = []
        for steps in STEPS:
            x, wall = run(sim, final_time / steps, steps)
            err = None if x is None else float(np.sqrt(np.mean(np.sum((x - x_ref) ** 2, 1))))
            points.append((final_time / steps, err, wall))
            rows.append({"scene": name, "integrator": integrator, "dt": final_time / steps,
                         "steps": steps, "error_m": "unstable" if err is None else err,
                         "wall_s": wall})
        results[integrator] = points
        p = order(points)
        print(f"accuracy.{name}.{integrator}.order: {p:.2f}", flush=True)
        for dt, err, wall in points:
            print(f"accuracy.{name}.{integrator}.dt{dt:.3g}.error_m: "
                  f"{'unstable' if err is None else f'{err:.3g}'} wall_s: {wall:.3g}")
    for level in (1e-2, 1e-3, 1e-4):
        best = min(((wall, integrator) for integrator, pts in results.items()
                    for _, err, wall in pts if err is not None and err <= level),
                   default=None)
        print(f"accuracy.{name}.cheapest_at_{level:g}: "
              f"{'none' if best is None else f'{best[1]} ({best[0] * 1e3:.1f} ms)'}")
    return rows, results


def plot(name, results, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax_t, ax_dt) = plt.subplots(1, 2, figsize=(12, 4.5))
    for integrator, points in results.items():
        pts = [(dt, err, wall) for dt, err, wall in points if err is not None and err > 0]
        if not pts:
            continue
        dt, err, wall = np.array(pts).T
        label = f"{integrator} (order {order(points):.2f})"
        ax_t.plot(wall, err, "o-", label=label)
        ax_dt.plot(dt, err, "o-", label=label)
    ax_t.set(xscale="log", yscale="log", xlabel="wall time (s)", ylabel="RMS error (m)",
             title=f"{name}: error against run time")
    ax_dt.set(xscale="log", yscale="log", xlabel="dt (s)", ylabel="RMS error (m)",
              title="error against dt (missing points: unstable)")
    ax_t.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    print(f"# wrote {path}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--time", type=float, default=0.5)
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--out", default="docs")
    args = ap.parse_args(argv)
    tcloth.init(precision="f64")
    os.makedirs(os.path.join(args.out, "img"), exist_ok=True)
    all_rows = []
    for name in args.scenes.split(","):
        rows, results = study(name, SCENES[name], args.time)
        all_rows += rows
        plot(name, results, os.path.join(args.out, "img", f"accuracy_{name}.png"))
    write_csv(os.path.join(args.out, "accuracy.csv"), all_rows)


if __name__ == "__main__":
    main()
