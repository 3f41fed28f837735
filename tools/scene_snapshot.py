"""Positions after 100 steps of every scene script, for the regression test
``tests/test_scene_regression.py``: each scene built with its default parameters and run
with its CONFIG integrator and dt, in float32 on the CPU.

Usage: python tools/scene_snapshot.py [--steps 100] [--out tests/data/scene_positions.npz]
(--compare FILE prints the largest difference against a stored snapshot instead;
--integrator NAME --dt DT run every scene with another integrator).
"""
import argparse
import glob
import os

import numpy as np

import tcloth
from tcloth.cli import load_script

HERE = os.path.dirname(os.path.abspath(__file__))
SCENES = os.path.join(HERE, "..", "scenes")


def snapshot(steps=100, integrator=None, dt=None):
    """dict scene name -> (N,3) positions after ``steps`` steps; integrator and dt replace
    the scenes' own where given."""
    out = {}
    for path in sorted(glob.glob(os.path.join(SCENES, "*.py"))):
        module, cfg = load_script(path)
        sim = tcloth.Simulator(module.build(), integrator=integrator or cfg["integrator"],
                               dt=dt or cfg["dt"])
        sim.step(steps)
        out[os.path.splitext(os.path.basename(path))[0]] = sim.positions()
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--out", default=os.path.join(HERE, "..", "tests", "data",
                                                  "scene_positions.npz"))
    ap.add_argument("--compare", default=None)
    ap.add_argument("--integrator", default=None)
    ap.add_argument("--dt", type=float, default=None)
    args = ap.parse_args(argv)
    tcloth.init(arch="cpu", precision="f32")
    positions = snapshot(args.steps, args.integrator, args.dt)
    if args.compare:
        stored = np.load(args.compare)
        for name, x in positions.items():
            if name not in stored.files:
                print(f"scene_snapshot.{name}: not in {args.compare} (a new scene)")
                continue
            diff = np.abs(x - stored[name]).max()
            print(f"scene_snapshot.{name}.max_abs_diff_m: {diff:.3g}"
                  f" ({'bit for bit' if np.array_equal(x, stored[name]) else 'differs'})")
        return
    np.savez(args.out, **positions)
    print(f"wrote {args.out}: {', '.join(positions)}")


if __name__ == "__main__":
    main()
