"""Positions of every scene script after SECONDS of simulated time, for the regression test
``tests/test_scene_regression.py``: each scene built with its default parameters and run
with its CONFIG integrator and dt, in float64 on the CPU.

The stored snapshot is compared within TOLERANCE (m), not bit for bit: a CPU with other
vector units (AVX-512 against AVX2) or another libm rounds some operations differently,
and a contact-rich scene amplifies the difference. Float64 keeps that far below what a
real change does (docs/benchmarks.md, "Fast math and the scene snapshots"):
  - perturbing the initial positions by 1e-15 m (a few float64 ulps) moves the most
    chaotic scene (cloth_pile) by 5.5e-13 m after 0.1 s;
  - a spring constant changed by 1e-3 moves every scene whose springs are loaded within
    0.1 s by 2.6e-8 m (tablecloth) to 1.3e-5 m (cloth_pile).
SECONDS is short enough that the folding and piling scenes have not yet turned chaotic
(after 0.15 s a 1e-15 m perturbation grows to 2e-4 m in fold).

Usage: python tools/scene_snapshot.py [--seconds 0.1] [--out tests/data/scene_positions.npz]
(--compare FILE prints the largest difference against a stored snapshot instead;
--integrator NAME --dt DT run every scene with another integrator; --stiffness-scale S
multiplies the structural springs' constant by S; --scenes a,b runs only those, and
without --compare adds them to --out, keeping the other scenes' positions).
"""
import argparse
import glob
import os

import numpy as np

import tcloth
from tcloth.app.script import load_script
from tcloth.scene.scene import KIND_CODE

HERE = os.path.dirname(os.path.abspath(__file__))
SCENES = os.path.join(HERE, "..", "scenes")
SECONDS = 0.1
TOLERANCE = 1e-9


def scene_names():
    return sorted(os.path.splitext(os.path.basename(p))[0]
                  for p in glob.glob(os.path.join(SCENES, "*.py")))


def scale_structural(scene, factor):
    """Multiply the structural springs' constant k_s by ``factor`` (a real change, for the
    tolerance test); the scene's structural springs must share one k_s."""
    springs = scene.springs
    ks = np.unique(springs["stiffness"][springs["kind"] == KIND_CODE["structural"]])
    if len(ks) != 1:
        raise ValueError(f"the structural springs have {len(ks)} constants, not one")
    scene.set_spring_parameters("structural", stiffness=float(ks[0]) * factor)


def run_scene(name, seconds=SECONDS, integrator=None, dt=None, stiffness_scale=1.0):
    """(N,3) positions of scenes/NAME.py after ``seconds``; integrator and dt replace the
    scene's own where given. Needs tcloth.init(precision="f64") for the stored snapshot."""
    module, cfg = load_script(os.path.join(SCENES, name + ".py"))
    scene = module.build()
    if stiffness_scale != 1.0:
        scale_structural(scene, stiffness_scale)
    dt = dt or cfg["dt"]
    sim = tcloth.Simulator(scene, integrator=integrator or cfg["integrator"], dt=dt,
                           **({} if integrator else cfg["options"]))
    sim.step(int(round(seconds / dt)))
    return sim.positions()


def snapshot(seconds=SECONDS, integrator=None, dt=None, stiffness_scale=1.0, names=None):
    """dict scene name -> ``run_scene``'s positions (of every scene, or of ``names``)."""
    return {name: run_scene(name, seconds, integrator, dt, stiffness_scale)
            for name in names or scene_names()}


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
