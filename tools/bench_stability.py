"""Stability stress maps: for each integrator, stable or not over a grid of (k_s, dt) on a
hanging 8 x 8 cloth (all spring families at k_s, k_d = --kd), with the explicit limit
dt = 2 / omega_max drawn on it, omega_max^2 the largest eigenvalue of M^-1 K at rest
(K assembled and solved here with NumPy, independently of tcloth's force code). Then the
symplectic Euler limit found by bisection against 2 / omega_max; damping sweeps: the
largest stable dt against k_d for each explicit integrator; and the lecture's claim that
forward Euler with k_d = 0 is unstable at every dt: the energy it creates in --seconds
against dt (positive at every dt, falling only in proportion to dt, so any dt blows up
given time), beside symplectic Euler's.

A run of --seconds (at most --max-steps steps) is unstable when it raises
InstabilityError or its total energy ends more than 1 % of M g L (cloth weight times
size) above the start: with no damping nothing may gain energy, and with damping the
total can only fall.

Prints greppable lines ``stability.<metric>: value``; writes <out>/stability.csv and
<out>/img/stability_map.png, <out>/img/stability_damping.png (matplotlib).

Usage: python tools/bench_stability.py [--kd 0] [--seconds 1] [--out docs]
"""
import argparse
import os

import numpy as np

import tcloth
from benchcsv import write_csv

INTEGRATORS = ["forward_euler", "symplectic_euler", "verlet", "rk4", "backward_euler",
               "projective"]
N, SIZE, MASS = 8, 0.5, 0.2


def scene(k, kd):
    s = tcloth.Scene()
    s.add_cloth(resolution=(N, N), size=(SIZE, SIZE), plane="xy", mass=MASS,
                structural=(k, kd), shear=(k, kd), flexion=(k, kd))
    return s


def omega_max(sc):
    """sqrt of the largest eigenvalue of M^-1 K for the free particles at rest."""
    x, springs = sc.positions, sc.springs
    n = len(x)
    stiffness = np.zeros((3 * n, 3 * n))
    for (i, j), k in zip(springs["pairs"], springs["stiffness"]):
        d = x[i] - x[j]
        d /= np.linalg.norm(d)
        block = k * np.outer(d, d)
        for a, b, sign in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
            stiffness[3 * a:3 * a + 3, 3 * b:3 * b + 3] += sign * block
    free = np.repeat(~sc.pinned, 3)
    scale = 1.0 / np.sqrt(np.repeat(sc.masses, 3)[free])
    reduced = stiffness[np.ix_(free, free)] * scale[:, None] * scale[None, :]
    return float(np.sqrt(np.linalg.eigvalsh(reduced)[-1]))


class Runner:
    """One Simulator per (integrator, k_s, k_d), reused across dt (reset to the start)."""

    def __init__(self, seconds, max_steps):
        self.seconds, self.max_steps = seconds, max_steps
        self.sims = {}

    def stable(self, integrator, k, kd, dt):
        key = (integrator, k, kd)
        if key not in self.sims:
            self.sims[key] = tcloth.Simulator(scene(k, kd), integrator, dt=dt)
        sim = self.sims[key]
        sim.reset(dt)
        e0 = sim.energy()["total"]
        allowed = 0.01 * MASS * 9.81 * SIZE
        try:
            sim.step(int(min(np.ceil(self.seconds / dt), self.max_steps)))
        except tcloth.InstabilityError:
            return False
        e1 = sim.energy()["total"]
        return bool(np.isfinite(e1) and e1 <= e0 + allowed)


def bisect_limit(runner, integrator, k, kd, lo, hi, iterations=10):
    """Largest stable dt in [lo, hi] by bisection in log dt (lo stable, hi unstable)."""
    for _ in range(iterations):
        mid = np.sqrt(lo * hi)
        lo, hi = (mid, hi) if runner.stable(integrator, k, kd, mid) else (lo, mid)
    return lo


def energy_gain(integrator, k, dt, seconds):
    """(E(seconds) - E(0)) / (M g L) with k_d = 0 and no drag: energy created."""
    sc = scene(k, 0.0)
    sim = tcloth.Simulator(sc, integrator, dt=dt)
    e0 = sim.energy()["total"]
    try:
        sim.step(int(round(seconds / dt)))
    except tcloth.InstabilityError:
        return float("inf")
    return (sim.energy()["total"] - e0) / (MASS * 9.81 * SIZE)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kd", type=float, default=0.0)
    ap.add_argument("--seconds", type=float, default=1.0)
    ap.add_argument("--max-steps", type=int, default=3000)
    ap.add_argument("--out", default="docs")
    args = ap.parse_args(argv)
    tcloth.init(precision="f64")
    runner = Runner(args.seconds, args.max_steps)
    ks = np.logspace(1, 5, 5)
    dts = np.logspace(-4, np.log10(1 / 30), 11)
    rows = []
    for integrator in INTEGRATORS:
        for k in ks:
            for dt in dts:
                ok = runner.stable(integrator, k, args.kd, dt)
                rows.append({"integrator": integrator, "k_s": k, "k_d": args.kd, "dt": dt,
                             "stable": int(ok)})
            stable_dts = [r["dt"] for r in rows[-len(dts):] if r["stable"]]
            print(f"stability.{integrator}.k{k:g}.largest_stable_dt: "
                  f"{max(stable_dts) if stable_dts else 0:.3g}", flush=True)
    limits = []
    for k in ks:
        w = omega_max(scene(k, args.kd))
        theory = 2.0 / w
        measured = bisect_limit(runner, "symplectic_euler", k, args.kd, theory / 4, theory * 4)
        limits.append({"k_s": k, "omega_max": w, "theory_dt": theory, "measured_dt": measured})
        print(f"stability.symplectic_euler.k{k:g}.measured_over_theory: "
              f"{measured / theory:.3f}", flush=True)
    kds = [0.0, 0.01, 0.1, 1.0, 3.0]
    sweep = []
    for integrator in INTEGRATORS[:4]:
        for kd in kds:
            theory = 2.0 / omega_max(scene(1e3, kd))
            limit = bisect_limit(runner, integrator, 1e3, kd, theory / 64, theory * 8)
            stable_low = runner.stable(integrator, 1e3, kd, theory / 64)
            sweep.append({"integrator": integrator, "k_d": kd,
                          "largest_stable_dt": limit if stable_low else 0.0})
            print(f"stability.damping.{integrator}.kd{kd:g}.largest_stable_dt: "
                  f"{sweep[-1]['largest_stable_dt']:.3g}", flush=True)
    gains = []
    for dt in np.logspace(-5, -3, 5):
        row = {"dt": dt}
        for integrator in ("forward_euler", "symplectic_euler"):
            row[integrator] = energy_gain(integrator, 1e3, dt, args.seconds)
            print(f"stability.kd0_energy_gain.{integrator}.dt{dt:.3g}: "
                  f"{row[integrator]:.3g}", flush=True)
        gains.append(row)
    os.makedirs(os.path.join(args.out, "img"), exist_ok=True)
    write_csv(os.path.join(args.out, "stability_kd0_energy_gain.csv"), gains)
    write_csv(os.path.join(args.out, "stability.csv"), rows)
    write_csv(os.path.join(args.out, "stability_limits.csv"), limits)
    write_csv(os.path.join(args.out, "stability_damping.csv"), sweep)
    _plot(rows, limits, sweep, ks, dts, args)


def _plot(rows, limits, sweep, ks, dts, args):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(2, 3, figsize=(13, 7.5), sharex=True, sharey=True)
    theory_k = np.logspace(1, 5, 50)
    theory_dt = [2.0 / omega_max(scene(k, args.kd)) for k in theory_k]
    for ax, integrator in zip(axes.flat, INTEGRATORS):
        cells = [r for r in rows if r["integrator"] == integrator]
        for r in cells:
            ax.scatter(r["k_s"], r["dt"], c="tab:green" if r["stable"] else "tab:red",
                       marker="o" if r["stable"] else "x", s=30)
        ax.plot(theory_k, theory_dt, "k--", lw=1, label="2 / omega_max")
        ax.set(xscale="log", yscale="log", title=integrator)
    for ax in axes[1]:
        ax.set_xlabel("k_s (N/m)")
    for ax in axes[:, 0]:
        ax.set_ylabel("dt (s)")
    axes[0, 0].legend(fontsize=8, loc="lower left")
    fig.suptitle(f"stable (green o) / unstable (red x), 8x8 hanging cloth, k_d = {args.kd:g}")
    fig.tight_layout()
    path = os.path.join(args.out, "img", "stability_map.png")
    fig.savefig(path, dpi=90)
    print(f"# wrote {path}")
    fig, ax = plt.subplots(figsize=(6, 4))
    for integrator in INTEGRATORS[:4]:
        pts = [r for r in sweep if r["integrator"] == integrator]
        ax.plot([max(r["k_d"], 1e-3) for r in pts],
                [max(r["largest_stable_dt"], 1e-6) for r in pts], "o-", label=integrator)
    ax.set(xscale="log", yscale="log", xlabel="k_d (N s/m; 0 drawn at 1e-3)",
           ylabel="largest stable dt (s; 0 drawn at 1e-6)", title="k_s = 1000")
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = os.path.join(args.out, "img", "stability_damping.png")
    fig.savefig(path, dpi=90)
    print(f"# wrote {path}")


if __name__ == "__main__":
    main()
