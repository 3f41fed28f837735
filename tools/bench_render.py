"""End-to-end frame rate of the main job: simulate, render and encode a 64 x 64 cloth on a
sphere at 640 x 480 (issue: >= 30 frames/s on a 2-core CPU). Prints greppable lines:

    render_bench.<case>.<metric>: value

Usage: python tools/bench_render.py [--frames 60] [--arch cpu] [--out out/bench]
"""
import argparse
import os
import sys

import tcloth

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "scenes"))
import cloth_on_sphere  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--arch", default="cpu")
    ap.add_argument("--out", default=os.path.join("out", "bench"))
    args = ap.parse_args(argv)
    tcloth.init(arch=args.arch)
    cases = [("ss1_steps1", 1, 1), ("ss1_steps5", 1, 5), ("ss1_steps10", 1, 10),
             ("ss2_steps5", 2, 5)]
    for name, ss, steps in cases:
        sim = tcloth.Simulator(cloth_on_sphere.build(resolution=(64, 64)), dt=2e-4)
        tcloth.record(sim, os.path.join(args.out, "warmup.mp4"), frames=3, steps_per_frame=1,
                      supersample=ss, camera=cloth_on_sphere.CONFIG["camera"], progress=False)
        s = tcloth.record(sim, os.path.join(args.out, name + ".mp4"), frames=args.frames,
                          steps_per_frame=steps, supersample=ss,
                          camera=cloth_on_sphere.CONFIG["camera"], progress=False)
        total = s["median_sim_ms"] + s["median_render_ms"] + s["median_encode_ms"]
        for key in ("median_sim_ms", "median_render_ms", "median_encode_ms"):
            print(f"render_bench.{name}.{key}: {s[key]:.2f}")
        print(f"render_bench.{name}.median_frame_ms: {total:.2f}")
        print(f"render_bench.{name}.fps_from_medians: {1e3 / total:.1f}")
        print(f"render_bench.{name}.fps_end_to_end: {s['fps']:.1f}")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
