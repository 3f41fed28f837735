"""What tearing costs where nothing breaks: ms per step of a hanging cloth (n x n, 1 m,
structural + shear + flexion springs, two corners pinned) with ``Scene.set_tearing`` on
(a threshold no spring reaches) against the same cloth without it, per integrator, all
measured side by side in one run: each configuration timed in --rounds interleaved
rounds of --steps steps (medians).

Four configurations an integrator: ``off`` and ``on`` as users get them (grid stencil,
batches where the scene allows them), and ``off_unbatched`` and ``on_unbatched``
(``batch=False``: a launch a kernel, the tearing kernel one more a step).

Prints greppable lines ``tearing_cost.<integrator>.<config>.ms_per_step: value`` and
``tearing_cost.<integrator>.<on_over_off|on_over_off_unbatched>: ratio``.

Usage: python tools/bench_tearing.py [--n 32] [--steps 50] [--rounds 7]
                                     [--integrators symplectic_euler,projective,xpbd]
"""
import argparse
import time

import numpy as np

import tcloth

DT = {"symplectic_euler": 2.5e-4, "verlet": 2.5e-4, "projective": 1 / 240,
      "xpbd": 1 / 60, "vbd": 1 / 60, "backward_euler": 1 / 120}
CONFIGS = {"off": (False, {}), "on": (True, {}), "off_unbatched": (False, {"batch": False}),
           "on_unbatched": (True, {"batch": False})}


def scene(n, tearing):
    s = tcloth.Scene(gravity=(0.0, -9.81, 0.0), air_damping=0.5)
    s.add_cloth(resolution=(n, n), size=(1.0, 1.0), center=(0.0, 1.0, 0.0), plane="xy",
                mass=0.2, structural=(400.0, 0.05), shear=(80.0, 0.02),
                flexion=(10.0, 0.005), pinned=[(0, 0), (n - 1, 0)])
    if tearing:
        s.set_tearing(max_strain=10.0)
    return s


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=32)
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--integrators", default="symplectic_euler,projective,xpbd")
    args = ap.parse_args(argv)
    tcloth.init()
    for integrator in args.integrators.split(","):
        sims = {}
        for name, (tearing, options) in CONFIGS.items():
            sims[name] = tcloth.Simulator(scene(args.n, tearing), integrator,
                                          dt=DT[integrator], **options)
            sims[name].step(args.steps)                      # compile, settle
        times = {name: [] for name in sims}
        for _ in range(args.rounds):
            for name, sim in sims.items():
                start = time.perf_counter()
                sim.step(args.steps)
                sim.positions()                               # waits for the device
                times[name].append((time.perf_counter() - start) / args.steps * 1e3)
        assert not any(len(sim.torn()) for sim in sims.values())
        ms = {name: float(np.median(t)) for name, t in times.items()}
        for name, value in ms.items():
            print(f"tearing_cost.{integrator}.{name}.ms_per_step: {value:.4f}")
        print(f"tearing_cost.{integrator}.on_over_off: {ms['on'] / ms['off']:.3f}")
        print(f"tearing_cost.{integrator}.on_over_off_unbatched: "
              f"{ms['on_unbatched'] / ms['off_unbatched']:.3f}")


if __name__ == "__main__":
    main()
