"""Stability stress maps: for each integrator, stable or not over a grid of (k_s, dt) on a
hanging 8 x 8 cloth (all spring families at k_s, k_d = --kd), with the explicit limit
dt = 2 / omega_max drawn on it, omega_max^2 the largest eigenvalue of M^-1 K at rest
(``tcloth.stability``: K assembled and solved with NumPy, independently of tcloth's force
code). Then the
symplectic Euler limit found by bisection against 2 / omega_max; damping sweeps: the
largest stable dt against k_d for each explicit integrator; and the lecture's claim that
forward Euler with k_d = 0 is unstable at every dt: the energy it creates in --seconds
against dt (positive at every dt, falling only in proportion to dt, so any dt blows up
given time), beside symplectic Euler's.

A run of --seconds (at most --max-steps steps) is unstable when it raises
InstabilityError or its total energy ends more than 1 % of M g L (cloth weight times
size) above the start: with no damping nothing may gain energy, and with damping the
total can only fall.

Every run goes through the sweep engine (``tcloth.sweep``): the map is one sweep, each
bisection round one sweep over all the limits being bisected, in parallel on --workers
processes; finished runs are kept in --work, so an interrupted study resumes.

Prints greppable lines ``stability.<metric>: value``; writes <out>/stability.csv and
<out>/img/stability_map.png, <out>/img/stability_damping.png (matplotlib).

Usage: python tools/bench_stability.py [--kd 0] [--seconds 1] [--out docs]
       [--workers N] [--work out/bench_stability]
"""
import argparse
import os

import numpy as np

from benchcsv import write_csv
from tcloth.app.script import load_script
from tcloth.scene.stability import omega_max
from tcloth.app.sweep import Runner, load_spec
from tcloth.app.sweep.plots import stability_map

HERE = os.path.dirname(os.path.abspath(__file__))
SCENE = os.path.join(HERE, "sweeps", "stability_cloth.py")
INTEGRATORS = ["forward_euler", "symplectic_euler", "verlet", "rk4", "backward_euler",
               "projective", "vbd", "xpbd"]
SIZE, MASS = 0.5, 0.2
MGL = MASS * 9.81 * SIZE


def spec(args, vary, **extra):
    """A sweep over ``vary`` on the tool's cloth, float64, stable = finite and energy
    grown by at most 1 % of M g L within --seconds (at most --max-steps steps)."""
    return load_spec({"scene": SCENE, "duration": args.seconds, "precision": "f64",
                      "max_steps": args.max_steps, "energy_limit": 0.01 * MGL,
                      "vary": vary, **extra})


def stability_map_spec(args):
    """The map: every integrator x 5 stiffnesses x 11 dt from 1e-4 to 1/30 s, k_d =
    --kd."""
    return spec(args, {"integrator": INTEGRATORS,
                       "k": [float(k) for k in np.logspace(1, 5, 5)],
                       "dt": [float(dt) for dt in np.logspace(-4, np.log10(1 / 30), 11)]},
                build={"kd": args.kd})


def points(runner, args, name, settings):
    """Stable or not for each dict of settings (integrator, k, kd, dt), one sweep."""
    rows = runner.run(spec(args, {"point": [dict(s, label=str(i))
                                            for i, s in enumerate(settings)]}),
                      os.path.join(args.work, name))
    return [bool(r["stable"]) for r in rows]


def bisect(runner, args, targets, iterations=10):
    """Largest stable dt of each target (integrator, k, kd, lo stable, hi unstable), by
    bisection in log dt: all targets advance together, one sweep per halving."""
    lo = np.array([t["lo"] for t in targets])
    hi = np.array([t["hi"] for t in targets])
    for _ in range(iterations):
        mid = np.sqrt(lo * hi)
        ok = np.array(points(runner, args, "bisect", [
            {"integrator": t["integrator"], "k": t["k"], "kd": t["kd"], "dt": float(m)}
            for t, m in zip(targets, mid)]))
        lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
    return lo


def scene(k):
    """The cloth at stiffness k (damping does not enter 2 / omega_max)."""
    module, _ = load_script(SCENE)
    return module.build(k=k)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kd", type=float, default=0.0)
    ap.add_argument("--seconds", type=float, default=1.0)
    ap.add_argument("--max-steps", type=int, default=3000)
    ap.add_argument("--out", default="docs")
    ap.add_argument("--workers", type=int, help="worker processes (default: one per core)")
    ap.add_argument("--work", default=os.path.join("out", "bench_stability"),
                    help="the sweeps' folder (finished runs are reused)")
    args = ap.parse_args(argv)
    map_spec = stability_map_spec(args)
    ks = map_spec.data["vary"]["k"]
    with Runner(workers=args.workers) as runner:
        map_rows = runner.run(map_spec, os.path.join(args.work, "map"))
        rows = [{"integrator": r["integrator"], "k_s": float(r["k"]), "k_d": args.kd,
                 "dt": r["dt"], "stable": int(bool(r["stable"]))} for r in map_rows]
        for integrator in INTEGRATORS:
            for k in ks:
                stable_dts = [r["dt"] for r in rows if r["integrator"] == integrator
                              and r["k_s"] == k and r["stable"]]
                print(f"stability.{integrator}.k{k:g}.largest_stable_dt: "
                      f"{max(stable_dts) if stable_dts else 0:.3g}", flush=True)
        theory = {k: 2.0 / omega_max(scene(k)) for k in ks + [1e3]}
        kds = [0.0, 0.01, 0.1, 1.0, 3.0]
        targets = [{"integrator": "symplectic_euler", "k": k, "kd": args.kd,
                    "lo": theory[k] / 4, "hi": theory[k] * 4} for k in ks]
        damped = [{"integrator": i, "k": 1e3, "kd": kd, "lo": theory[1e3] / 64,
                   "hi": theory[1e3] * 8} for i in INTEGRATORS[:4] for kd in kds]
        found = bisect(runner, args, targets + damped)
        stable_low = points(runner, args, "lowest", [
            {"integrator": t["integrator"], "k": t["k"], "kd": t["kd"], "dt": t["lo"]}
            for t in damped])
        gain_rows = runner.run(spec(args, {"integrator": ["forward_euler", "symplectic_euler"],
                                           "dt": [float(dt) for dt in np.logspace(-5, -3, 5)]},
                                    build={"kd": 0.0}, max_steps=None, energy_limit=None),
                               os.path.join(args.work, "energy_gain"))
    limits = []
    for t, measured in zip(targets, found[:len(targets)]):
        w = 2.0 / theory[t["k"]]
        limits.append({"k_s": t["k"], "omega_max": w, "theory_dt": 2.0 / w,
                       "measured_dt": float(measured)})
        print(f"stability.symplectic_euler.k{t['k']:g}.measured_over_theory: "
              f"{measured * w / 2.0:.3f}", flush=True)
    sweep = []
    for t, measured, ok in zip(damped, found[len(targets):], stable_low):
        sweep.append({"integrator": t["integrator"], "k_d": t["kd"],
                      "largest_stable_dt": float(measured) if ok else 0.0})
        print(f"stability.damping.{t['integrator']}.kd{t['kd']:g}.largest_stable_dt: "
              f"{sweep[-1]['largest_stable_dt']:.3g}", flush=True)
    gains = {}
    for r in gain_rows:
        gain = r["energy_drift"] / MGL if r["status"] == "ok" else float("inf")
        gains.setdefault(r["dt"], {"dt": r["dt"]})[r["integrator"]] = gain
        print(f"stability.kd0_energy_gain.{r['integrator']}.dt{r['dt']:.3g}: {gain:.3g}",
              flush=True)
    os.makedirs(os.path.join(args.out, "img"), exist_ok=True)
    write_csv(os.path.join(args.out, "stability_kd0_energy_gain.csv"), list(gains.values()))
    write_csv(os.path.join(args.out, "stability.csv"), rows)
    write_csv(os.path.join(args.out, "stability_limits.csv"), limits)
    write_csv(os.path.join(args.out, "stability_damping.csv"), sweep)
    path = os.path.join(args.out, "img", "stability_map.png")
    stability_map(map_spec, map_rows, "k", path)
    print(f"# wrote {path}")
    _plot_damping(sweep, os.path.join(args.out, "img", "stability_damping.png"))


def _plot_damping(sweep, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 4))
    for integrator in INTEGRATORS[:4]:
        pts = [r for r in sweep if r["integrator"] == integrator]
        ax.plot([max(r["k_d"], 1e-3) for r in pts],
                [max(r["largest_stable_dt"], 1e-6) for r in pts], "o-", label=integrator)
    ax.set(xscale="log", yscale="log", xlabel="k_d (N s/m; 0 drawn at 1e-3)",
           ylabel="largest stable dt (s; 0 drawn at 1e-6)", title="k_s = 1000")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    print(f"# wrote {path}")


if __name__ == "__main__":
    main()
