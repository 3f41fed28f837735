"""The sweep engine's speed-up: bench_stability.py's default stability map (6 integrators x
5 stiffnesses x 11 dt, 330 runs of an 8 x 8 cloth, float64) run serially in one process
and on a local pool of --workers processes, side by side, each from an empty output
folder (everything counted: the pool's start, the workers' imports and compiling).
Prints greppable lines

    sweep.map.<serial_s|pool_s|pool_over_serial>: value

(medians over --repeats alternating pairs).

Usage: python tools/bench_sweep.py [--workers 2] [--repeats 1]
"""
import argparse
import shutil
import tempfile
import time

import numpy as np

from bench_stability import stability_map_spec
from tcloth.app.sweep import run_sweep


def timed(map_spec, workers):
    out = tempfile.mkdtemp(prefix="bench_sweep-")
    try:
        t0 = time.perf_counter()
        run_sweep(map_spec, out, workers=workers, progress=False)
        return time.perf_counter() - t0
    finally:
        shutil.rmtree(out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--seconds", type=float, default=1.0)
    ap.add_argument("--max-steps", type=int, default=3000)
    ap.add_argument("--kd", type=float, default=0.0)
    args = ap.parse_args(argv)
    map_spec = stability_map_spec(args)
    serial, pool = [], []
    for _ in range(args.repeats):
        serial.append(timed(map_spec, 1))
        print(f"# serial {serial[-1]:.1f} s", flush=True)
        pool.append(timed(map_spec, args.workers))
        print(f"# pool of {args.workers}: {pool[-1]:.1f} s", flush=True)
    print(f"sweep.map.serial_s: {np.median(serial):.1f}")
    print(f"sweep.map.pool_s: {np.median(pool):.1f}")
    print(f"sweep.map.pool_over_serial: {np.median(pool) / np.median(serial):.3f}")


if __name__ == "__main__":
    main()
