"""Work-precision: for each integrator and a range of dt, the error at a fixed final time
against a reference (RK4 at a much smaller dt, float64) versus wall time, on a cloth
falling from horizontal and swinging from two corners, at two stiffnesses, and on a cloth
falling onto a sphere. Measured convergence
orders (least-squares slope of log error against log dt over the runs below 10 % error)
go into the legend, and the cheapest method at a few error levels is printed.

Error: RMS over particles of |x - x_ref| at t = --time, m. Wall time: the run alone
(each simulator is compiled by two untimed first steps and reset). Orders are fitted
over the stable runs with an error below 10 % of the scene's size.

Every scene is one sweep of the sweep engine (``tcloth.sweep``), run in parallel on
--workers processes; finished runs are kept in --work, so an interrupted study resumes.

Prints greppable lines ``accuracy.<scene>.<integrator>.<metric>: value``; writes
<out>/accuracy.csv and <out>/img/accuracy_<scene>.png (matplotlib).

Usage: python tools/bench_accuracy.py [--time 0.5] [--out docs] [--workers N]
       [--work out/bench_accuracy]
"""
import argparse
import os

from benchcsv import write_csv
from tcloth.app.sweep import Runner, load_spec
from tcloth.app.sweep.plots import order, scene_size, work_precision

HERE = os.path.dirname(os.path.abspath(__file__))
# label -> (integrator, options); backward Euler also with its Newton and CG tolerances
# tightened, so that its own time-discretisation error shows (the defaults stop Newton at
# a velocity change of 1e-4 m/s, an error floor); VBD at its default 10 iterations and at
# 40; XPBD at its default 10 iterations, one substep
METHODS = {"forward_euler": ("forward_euler", {}),
           "symplectic_euler": ("symplectic_euler", {}),
           "verlet": ("verlet", {}),
           "rk4": ("rk4", {}),
           "backward_euler": ("backward_euler", {}),
           "backward_euler_tight": ("backward_euler", {"newton_tol": 1e-9, "cg_tol": 1e-8}),
           "projective": ("projective", {}),
           "vbd": ("vbd", {}),
           "vbd_40": ("vbd", {"iterations": 40}),
           "xpbd": ("xpbd", {})}
STEPS = [25, 50, 100, 200, 400, 800, 1600, 3200]
REFERENCE_STEPS = 25600
# name -> (scene script in tools/sweeps, build parameters)
SCENES = {"swinging_k300": ("swinging_cloth.py", {"k": 300.0}),
          "swinging_k3000": ("swinging_cloth.py", {"k": 3000.0}),
          "cloth_on_sphere": ("cloth_on_sphere.py", {})}


def study_spec(name, final_time):
    script, build = SCENES[name]
    return load_spec({
        "scene": os.path.join(HERE, "sweeps", script), "duration": final_time,
        "precision": "f64", "build": build,
        "vary": {"method": [{"label": label, "integrator": integrator, "options": options}
                            for label, (integrator, options) in METHODS.items()],
                 "dt": [final_time / steps for steps in STEPS]},
        "reference": {"integrator": "rk4", "dt": final_time / REFERENCE_STEPS,
                      "precision": "f64"}})


def report(name, spec, rows):
    """Print the orders, errors and the cheapest method at a few error levels; the
    rows of accuracy.csv."""
    size = scene_size(spec)
    out = []
    for label in METHODS:
        runs = [r for r in rows if r["method"] == label]
        stable = [(r["dt"], r["error"]) for r in runs if r["stable"]]
        print(f"accuracy.{name}.{label}.order: {order(stable, size):.2f}", flush=True)
        for r in runs:
            wall = r["ms_per_step"] * r["steps"] / 1e3
            err = f"{r['error']:.3g}" if r["stable"] else "unstable"
            print(f"accuracy.{name}.{label}.dt{r['dt']:.3g}.error_m: {err} wall_s: {wall:.3g}")
            out.append({"scene": name, "integrator": label, "dt": r["dt"], "steps": r["steps"],
                        "error_m": r["error"] if r["stable"] else "unstable",
                        "wall_s": wall})
    for level in (1e-2, 1e-3, 1e-4):
        best = min(((r["wall_s"], r["integrator"]) for r in out
                    if r["error_m"] != "unstable" and r["error_m"] <= level), default=None)
        print(f"accuracy.{name}.cheapest_at_{level:g}: "
              f"{'none' if best is None else f'{best[1]} ({best[0] * 1e3:.1f} ms)'}")
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--time", type=float, default=0.5)
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--out", default="docs")
    ap.add_argument("--workers", type=int, help="worker processes (default: one per core)")
    ap.add_argument("--work", default=os.path.join("out", "bench_accuracy"),
                    help="the sweeps' folder (finished runs are reused)")
    args = ap.parse_args(argv)
    os.makedirs(os.path.join(args.out, "img"), exist_ok=True)
    all_rows = []
    with Runner(workers=args.workers) as runner:
        for name in args.scenes.split(","):
            spec = study_spec(name, args.time)
            rows = runner.run(spec, os.path.join(args.work, name))
            all_rows += report(name, spec, rows)
            path = os.path.join(args.out, "img", f"accuracy_{name}.png")
            work_precision(spec, rows, path)
            print(f"# wrote {path}")
    write_csv(os.path.join(args.out, "accuracy.csv"), all_rows)


if __name__ == "__main__":
    main()
