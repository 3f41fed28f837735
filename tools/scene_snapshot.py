"""Positions of every scene script after SECONDS of simulated time, for the regression test
``tests/test_scene_regression.py`` (``tcloth.testing.golden.snapshot``): each scene built
with its default parameters and run with its CONFIG integrator and dt, in float64 on the
CPU.

The tolerance and the time are argued in ``tcloth.testing.golden``.

Usage: python tools/scene_snapshot.py [--seconds 0.1] [--out tests/data/scene_positions.npz]
(--compare FILE prints the largest difference against a stored snapshot instead;
--integrator NAME --dt DT run every scene with another integrator; --stiffness-scale S
multiplies the structural springs' constant by S; --scenes a,b runs only those, and
without --compare adds them to --out, keeping the other scenes' positions).
"""
import argparse
import os

import numpy as np

import tcloth
from tcloth.testing.golden import SECONDS, TOLERANCE, snapshot

HERE = os.path.dirname(os.path.abspath(__file__))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=SECONDS)
    ap.add_argument("--out", default=os.path.join(HERE, "..", "tests", "data",
                                                  "scene_positions.npz"))
    ap.add_argument("--compare", default=None)
    ap.add_argument("--integrator", default=None)
    ap.add_argument("--dt", type=float, default=None)
    ap.add_argument("--stiffness-scale", type=float, default=1.0)
    ap.add_argument("--scenes", help="only these (a,b): a new scene added to --out, the "
                                     "others' positions kept")
    args = ap.parse_args(argv)
    tcloth.init(arch="cpu", precision="f64")
    names = args.scenes.split(",") if args.scenes else None
    positions = snapshot(args.seconds, args.integrator, args.dt, args.stiffness_scale, names)
    if names and not args.compare and os.path.exists(args.out):
        with np.load(args.out) as stored:
            positions = {**{key: stored[key] for key in stored.files}, **positions}
    if args.compare:
        stored = np.load(args.compare)
        for name, x in positions.items():
            if name not in stored.files:
                print(f"scene_snapshot.{name}: not in {args.compare} (a new scene)")
                continue
            diff = np.abs(x - stored[name]).max()
            print(f"scene_snapshot.{name}.max_abs_diff_m: {diff:.3g}"
                  f" ({'within' if diff <= TOLERANCE else 'beyond'} {TOLERANCE:g} m)")
        return
    np.savez(args.out, **positions)
    print(f"wrote {args.out}: {', '.join(positions)}")


if __name__ == "__main__":
    main()
