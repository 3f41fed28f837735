"""The sandbox window's frame rate: a 64 x 64 cloth on a sphere (scenes/cloth_on_sphere.py)
with 8 substeps a frame, the issue's target of 60 frames/s.

Prints the median frames/s over the last 30 frames, the simulation's share (ms per frame
of substeps) and the rest (drawing, the panel, the driver). It opens a window: without a
screen, run it under ``xvfb-run -a``.

Usage: python tools/bench_viewer.py [--frames 150] [--substeps 8] [--resolution 64]
       [--arch cpu] [--width 1280 --height 800]
"""
import argparse
import os

import numpy as np

import tcloth
from tcloth.cli import load_script
from tcloth.viewer import Viewer

HERE = os.path.dirname(os.path.abspath(__file__))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=150)
    parser.add_argument("--substeps", type=int, default=8)
    parser.add_argument("--resolution", type=int, default=64)
    parser.add_argument("--arch", default="cpu")
    parser.add_argument("--width", type=int, default=1280)
    parser.add_argument("--height", type=int, default=800)
    args = parser.parse_args()
    tcloth.init(arch=args.arch)
    module, cfg = load_script(os.path.join(HERE, "..", "scenes", "cloth_on_sphere.py"))
    scene = module.build(resolution=(args.resolution, args.resolution))
    sim = tcloth.Simulator(scene, cfg["integrator"], dt=cfg["dt"], grab=True)
    viewer = Viewer(sim, substeps=args.substeps, camera=cfg["camera"], width=args.width,
                    height=args.height)
    viewer.run(frames=args.frames)
    c = viewer.controls
    frame_ms = 1e3 * float(np.median(c.frame_seconds))
    sim_ms = 1e3 * args.substeps * float(np.median(c.substep_seconds))
    tag = f"viewer.{args.resolution}x{args.resolution}_{args.substeps}substeps"
    print(f"# arch {args.arch}, {args.width} x {args.height}, DISPLAY "
          f"{os.environ.get('DISPLAY')!r}")
    print(f"{tag}.frames_per_s: {1e3 / frame_ms:.1f}")
    print(f"{tag}.frame_ms: {frame_ms:.2f}")
    print(f"{tag}.simulation_ms: {sim_ms:.2f}")
    print(f"{tag}.drawing_and_panel_ms: {frame_ms - sim_ms:.2f}")


if __name__ == "__main__":
    main()
