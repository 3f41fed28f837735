"""The sandbox window's frame rate: a 64 x 64 cloth on a sphere (scenes/cloth_on_sphere.py)
with 8 substeps a frame, the issue's target of 60 frames/s.

Prints medians over the last 30 frames: frames/s, the simulation's ms per frame, tcloth's
other work per frame (positions, normals, the panel's numbers, GGUI's draw calls) and the
driver's (``window.show()``: rasterising and presenting), and the frames/s without the
driver's share (what a hardware Vulkan driver, whose share is small, approaches). It opens a window: without a
screen, run it under ``xvfb-run -a``.

The scene's dt (0.25 ms) is for its 48 x 48 cloth: the spring damping's explicit limit
scales with the particle mass, so the default dt is 0.25 ms min(1, (48 / resolution)^2) (at 64 x 64
0.25 ms blows up in the 35th step, and the window would draw a blown-up cloth).

Usage: xvfb-run -a python tools/bench_viewer.py [--frames 150] [--substeps 8]
       [--resolution 64] [--dt DT] [--arch cpu] [--width 1280 --height 800]
"""
import argparse
import os
import time

import numpy as np

import tcloth
from tcloth.app.script import load_script
from tcloth.viewer import Viewer

HERE = os.path.dirname(os.path.abspath(__file__))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=150)
    parser.add_argument("--substeps", type=int, default=8)
    parser.add_argument("--resolution", type=int, default=64)
    parser.add_argument("--dt", type=float, help="time step, s (default above)")
    parser.add_argument("--arch", default="cpu")
    parser.add_argument("--width", type=int, default=1280)
    parser.add_argument("--height", type=int, default=800)
    args = parser.parse_args()
    tcloth.init(arch=args.arch)
    module, cfg = load_script(os.path.join(HERE, "..", "scenes", "cloth_on_sphere.py"))
    scene = module.build(resolution=(args.resolution, args.resolution))
    dt = args.dt or cfg["dt"] * min(1.0, (48 / args.resolution) ** 2)
    sim = tcloth.Simulator(scene, cfg["integrator"], dt=dt, grab=True)
    viewer = Viewer(sim, substeps=args.substeps, camera=cfg["camera"], width=args.width,
                    height=args.height)
    frame, show = [], []
    for _ in range(args.frames):
        start = time.perf_counter()
        viewer.frame()
        drawn = time.perf_counter()
        viewer.window.show()
        frame.append(drawn - start)
        show.append(time.perf_counter() - drawn)
    c = viewer.controls
    if c.message:
        raise SystemExit(f"the run blew up: {c.message}")
    last = slice(-30, None)
    frame_ms, show_ms = 1e3 * np.median(frame[last]), 1e3 * np.median(show[last])
    sim_ms = 1e3 * args.substeps * float(np.median(c.substep_seconds))
    tag = f"viewer.{args.resolution}x{args.resolution}_{args.substeps}substeps"
    print(f"# arch {args.arch}, {args.width} x {args.height}, dt {dt:.3g} s, DISPLAY "
          f"{os.environ.get('DISPLAY')!r}")
    print(f"{tag}.frames_per_s: {1e3 / (frame_ms + show_ms):.1f}")
    print(f"{tag}.simulation_ms: {sim_ms:.2f}")
    print(f"{tag}.tcloth_other_ms: {frame_ms - sim_ms:.2f}")
    print(f"{tag}.driver_show_ms: {show_ms:.2f}")
    print(f"{tag}.frames_per_s_without_driver: {1e3 / frame_ms:.1f}")


if __name__ == "__main__":
    main()
