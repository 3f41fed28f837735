"""The sliding case (``tcloth.testing.contact_cases.sliding``): a small cloth slides over a
large one without friction, and should keep its speed.

A 0.3 m, 8 x 8 cloth of 20 g, dropped from 9 mm above a 1.2 m, 24 x 24 cloth of 0.3 kg
that lies on a frictionless floor, moves along it at 1 m/s; self-collision of 6 mm
without friction, gravity, 0.5 s. Nothing takes horizontal momentum from the two cloths
but the floor, which is frictionless, so the upper cloth should keep 1 m/s and the lower
stay at rest (the target: within 1 % with each frame-rate solver).

Usage: python tools/bench_sliding.py [--runs symplectic_euler:1e-4,projective:1/60,...]
                                     [--seconds 0.5] [--trace]
Prints, per run, the upper and lower cloths' mean velocity along the slide, the two
cloths' momentum along it (0.02 kg m/s at the start), the guard's corrections and the
wall time; --trace prints them after every step of a frame-rate run.
"""
import argparse
import time
from fractions import Fraction

import tcloth
from tcloth.testing.contact_cases import sliding

RUNS = "symplectic_euler:1e-4,projective:1/60,xpbd:1/60,vbd:1/60"


def report(sim, low, up):
    v = sim.velocities()
    return ("upper %.4f m/s, lower %.4f m/s, momentum %.5f kg m/s, guard corrections %d"
            % (v[up.particles.ravel(), 0].mean(), v[low.particles.ravel(), 0].mean(),
               sim.momentum()[0][0], sim.contact_stats()["guard_corrections"]))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", default=RUNS, help="integrator:dt pairs, comma-separated")
    ap.add_argument("--seconds", type=float, default=0.5)
    ap.add_argument("--trace", action="store_true")
    args = ap.parse_args()
    for run in args.runs.split(","):
        name, dt = run.split(":")
        dt = float(Fraction(dt))
        s, low, up, v = sliding()
        sim = tcloth.Simulator(s, name, dt=dt)
        sim.set_state(velocities=v)
        steps = int(round(args.seconds / dt))
        t0 = time.perf_counter()
        if args.trace and dt > 1e-3:
            for k in range(steps):
                sim.step(1)
                print(f"  {name} step {k}: {report(sim, low, up)}", flush=True)
        else:
            sim.step(steps)
        print(f"{name} dt={dt:.6g}, {args.seconds} s: {report(sim, low, up)}, "
              f"{time.perf_counter() - t0:.1f} s wall", flush=True)


if __name__ == "__main__":
    main()
