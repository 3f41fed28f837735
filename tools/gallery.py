"""Render the stills and short videos in docs/ from the scene scripts.

    python tools/gallery.py [--scenes a,b] [--videos]

Prints one ``gallery.<scene>.<metric>: value`` line per measurement.
"""
import argparse
import os
import sys

import tcloth
from tcloth.app.script import load_script

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# scene -> simulated seconds of its still
STILLS = {"hanging_cloth": 1.6, "cloth_on_sphere": 2.0, "cloth_on_box": 2.0, "rope": 0.4,
          "negative_examples": 2.0, "incline": 0.8, "sphere_through_cloth": 1.5,
          "flag": 2.5, "strain_limiting": 3.0, "orbit": 2.0, "cloth_pile": 1.5, "fold": 1.5,
          "tablecloth": 2.0, "curtain": 0.8, "table": 2.0, "turntable": 3.0, "breathing": 4.0,
          "garment": 2.0}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=",".join(STILLS))
    ap.add_argument("--videos", action="store_true", help="also 320x240 MP4s in docs/video")
    args = ap.parse_args(argv)
    for name in args.scenes.split(","):
        module, cfg = load_script(os.path.join(ROOT, "scenes", name + ".py"))
        tcloth.init(arch="cpu", precision=cfg["precision"])
        sim = tcloth.Simulator(module.build(), cfg["integrator"], dt=cfg["dt"], **cfg["options"])
        if args.videos:
            stats = tcloth.record(sim, os.path.join(ROOT, "docs", "video", name + ".mp4"),
                                  frames=cfg["frames"], steps_per_frame=cfg["steps_per_frame"],
                                  fps=cfg["fps"], width=320, height=240, camera=cfg["camera"],
                                  supersample=2, quality=6, progress=False, **cfg["render"])
            print(f"gallery.{name}.video_fps: {stats['fps']:.2f}")
            sim = tcloth.Simulator(module.build(), cfg["integrator"], dt=cfg["dt"],
                                   **cfg["options"])
        sim.step(int(round(STILLS[name] / cfg["dt"])))
        img = tcloth.render(sim, 640, 480, camera=cfg["camera"], supersample=3, **cfg["render"])
        tcloth.write_png(os.path.join(ROOT, "docs", "img", name + ".png"), img)
        print(f"gallery.{name}.still_time_s: {sim.time:.3f}")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
