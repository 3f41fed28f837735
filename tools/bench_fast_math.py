"""What Taichi's fast math would buy: the same steps with ``tcloth.init(fast_math=True)``
and with tcloth's default ``fast_math=False`` (IEEE arithmetic, the same numbers wherever
a function is inlined and on every CPU; ``runtime.init``).

Each round runs both settings in fresh processes one after the other; the medians over
rounds of each case's median ms per step are printed as greppable lines
``fast_math.<case>.<on|off>.ms_per_step: value`` and ``fast_math.<case>.off_over_on``.
Cases: symplectic Euler on Warp's benchmark cloth (0.1 m spacing, k = 1000, 16 substeps
a frame) at 32 x 32 and 128 x 128, backward Euler at 48 x 48 and dt = 1/60.

Usage: python tools/bench_fast_math.py [--rounds 3]
"""
import argparse
import json
import subprocess
import sys
import time

import numpy as np

CASES = (("symplectic_euler_32", "symplectic_euler", 32, 1 / 960, 2000),
         ("symplectic_euler_128", "symplectic_euler", 128, 1 / 960, 200),
         ("backward_euler_48", "backward_euler", 48, 1 / 60, 3))


def measure(fast_math):
    import tcloth
    tcloth.init(arch="cpu", precision="f32", fast_math=fast_math)
    out = {}
    for name, integrator, n, dt, steps in CASES:
        scene = tcloth.Scene()
        scene.add_cloth(resolution=(n, n), size=(0.1 * (n - 1),) * 2, mass=0.1 * n * n,
                        structural=(1000.0, 10.0), shear=(1000.0, 10.0),
                        flexion=(1000.0, 10.0))
        sim = tcloth.Simulator(scene, integrator, dt=dt)
        sim.step(steps)
        times = []
        for _ in range(7):
            t0 = time.perf_counter()
            sim.step(steps)
            times.append((time.perf_counter() - t0) / steps * 1e3)
        out[name] = float(np.median(times))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--child", choices=["on", "off"], help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(measure(args.child == "on")))
        return
    runs = {"on": [], "off": []}
    for _ in range(args.rounds):
        for setting in ("on", "off"):
            result = subprocess.run([sys.executable, __file__, "--child", setting],
                                    capture_output=True, text=True, check=True)
            runs[setting].append(json.loads(result.stdout.strip().splitlines()[-1]))
    for name, *_ in CASES:
        ms = {s: float(np.median([r[name] for r in runs[s]])) for s in runs}
        for s in ("on", "off"):
            print(f"fast_math.{name}.{s}.ms_per_step: {ms[s]:.4g}")
        print(f"fast_math.{name}.off_over_on: {ms['off'] / ms['on']:.3f}")


if __name__ == "__main__":
    main()
