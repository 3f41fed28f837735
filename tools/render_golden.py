"""The golden images of ``tests/test_render_golden.py``: every shipped scene at two moments,
its particles' positions there and the picture the renderer draws of them.

Each scene is built with its default parameters and simulated with its CONFIG (integrator,
dt, steps a frame) to the first whole frame at or past each of TIMES; its positions are
stored, and the picture is drawn of the state ``posed`` rebuilds from them (the scene's
colliders where they are at that time), at WIDTH x HEIGHT with supersampling 2 and the
scene's camera and render options. The test draws the same states again and compares.

Made with the renderer the others are compared against (the ray-casting one it replaced):

    PYTHONPATH=<a checkout of that renderer> python tools/render_golden.py

Usage: python tools/render_golden.py [--scenes a,b] [--out tests/data/render_golden.npz]
[--png DIR] (--png also writes each picture as DIR/<scene>_<k>.png, to look at). The
scenes named are drawn again (a new scene added); the others' pictures in --out are kept.
"""
import argparse
import glob
import os
import sys

import numpy as np

import tcloth
from tcloth.app.script import load_script, timing

HERE = os.path.dirname(os.path.abspath(__file__))
SCENES = os.path.join(HERE, "..", "scenes")
TIMES = (0.2, 1.5)            # s: the moments drawn
WIDTH, HEIGHT, SUPERSAMPLE = 160, 120, 2


def scene_names():
    return sorted(os.path.splitext(os.path.basename(p))[0]
                  for p in glob.glob(os.path.join(SCENES, "*.py")))


def script(name):
    """(module, CONFIG) of scenes/NAME.py."""
    return load_script(os.path.join(SCENES, name + ".py"))


def posed(module, dt, steps, positions, sim=None):
    """A Simulator of the script's scene (``sim``, or a new one with time step dt) as
    ``steps`` steps of dt in (none taken) with its particles at ``positions``: its
    colliders (moving, turning, keyframed, deforming) where they are at that time."""
    sim = sim or tcloth.Simulator(module.build(), "symplectic_euler", dt=dt)
    sim.num_steps = int(steps)
    if steps:
        sim.model.colliders.advance(sim.time - dt, dt)
    sim.set_state(positions=positions)
    return sim


def draw(sim, cfg, **options):
    """The golden picture of a simulator's state: WIDTH x HEIGHT, the scene's camera."""
    return tcloth.render(sim, WIDTH, HEIGHT, camera=cfg["camera"], supersample=SUPERSAMPLE,
                         **{**cfg["render"], **options})


def frames(name):
    """{<name>.dt, .steps (F,), .positions (F, N, 3) float32, .images (F, H, W, 3)}."""
    module, cfg = script(name)
    tcloth.init(arch="cpu", precision=cfg["precision"])
    scene = module.build()
    dt, per_frame = timing(cfg, scene)
    sim = tcloth.Simulator(scene, cfg["integrator"], dt=dt, **cfg["options"])
    steps, positions = [], []
    for moment in TIMES:
        target = int(np.ceil(moment * cfg["fps"] - 1e-9)) * per_frame
        sim.step(target - sim.num_steps)
        steps.append(sim.num_steps)
        positions.append(sim.positions().astype(np.float32))
    images = [draw(posed(module, dt, k, x), cfg) for k, x in zip(steps, positions)]
    return {f"{name}.dt": np.float64(dt), f"{name}.steps": np.array(steps),
            f"{name}.positions": np.stack(positions), f"{name}.images": np.stack(images)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=",".join(scene_names()))
    ap.add_argument("--out", default=os.path.join(HERE, "..", "tests", "data",
                                                  "render_golden.npz"))
    ap.add_argument("--png", help="also write each picture here as a PNG")
    args = ap.parse_args(argv)
    data = {}
    if os.path.exists(args.out):        # the other scenes' pictures are kept
        with np.load(args.out) as stored:
            data = {key: stored[key] for key in stored.files}
    for name in args.scenes.split(","):
        data.update(frames(name))
        print(f"render_golden.{name}.steps: {data[name + '.steps'].tolist()}")
        sys.stdout.flush()
        if args.png:
            os.makedirs(args.png, exist_ok=True)
            for k, image in enumerate(data[name + ".images"]):
                tcloth.write_png(os.path.join(args.png, f"{name}_{k}.png"), image)
    np.savez_compressed(args.out, **data)


if __name__ == "__main__":
    main()
