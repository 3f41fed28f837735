"""What a frame of ``tcloth render`` costs, scene by scene: the renderer's passes, the
encoders and the rate end to end.

For each shipped scene (or --scenes a,b): build it with its default parameters, simulate
--settle frames with its CONFIG (integrator, dt, steps a frame; ms a frame, wall and CPU
time on all threads), then
  - render that state --frames times (--width x --height, --supersample): ms a frame in
    all and by pass (``Renderer.timings``; a renderer without them gives its total), and
    the CPU time a frame takes on all threads together (on a shared machine the wall
    time grows with the others' load, the CPU time much less);
  - write that picture as a PNG (``write_png``), ms;
  - record --record more frames to an MP4 (``tcloth.record``): the medians of a frame's
    simulation, render and H.264 encoding, and frames/s end to end.
Prints one ``render_bench.<scene>.<metric>: value`` line per number (medians, ms).

    python tools/bench_render.py [--scenes table,flag] [--frames 10] [--record 20]
    python tools/bench_render.py --against OTHER_PYTHON [--rounds 2]

--against runs every scene in a process of its own, with this Python and with
OTHER_PYTHON (another checkout's venv: its tcloth, this file) in turn, --rounds times, and
prints both trees' medians side by side with their ratio, and a Markdown table.
"""
import argparse
import glob
import os
import statistics
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
SCENES = os.path.join(HERE, "..", "scenes")
SHOWN = ("sim_ms", "sim_cpu_ms", "render_ms", "render_cpu_ms", "png_ms", "h264_ms",
         "fps_end_to_end")


def scene_names():
    return sorted(os.path.splitext(os.path.basename(p))[0]
                  for p in glob.glob(os.path.join(SCENES, "*.py")))


def measure(name, args):
    """{metric: value} of one scene (module docstring), in this process."""
    import taichi as ti

    import tcloth
    from tcloth.app.script import load_script, timing
    from tcloth.render.render import renderer_for
    module, cfg = load_script(os.path.join(SCENES, name + ".py"))
    tcloth.init(arch=args.arch, precision=cfg["precision"])
    scene = module.build()
    dt, steps = timing(cfg, scene)
    sim = tcloth.Simulator(scene, cfg["integrator"], dt=dt, **cfg["options"])
    out = {"steps": steps}
    sim_s, sim_cpu = [], []
    for _ in range(args.settle):
        t0, c0 = time.perf_counter(), time.process_time()
        sim.step(steps)
        sim_s.append(time.perf_counter() - t0)
        sim_cpu.append(time.process_time() - c0)
    options = dict(width=args.width, height=args.height, camera=cfg["camera"],
                   supersample=args.supersample, **cfg["render"])
    renderer = renderer_for(sim, **options)
    image = renderer.render()                          # compiled, the static scene drawn
    renderer.timings, totals, cpu = {}, [], []
    for _ in range(args.frames):
        t0, c0 = time.perf_counter(), time.process_time()
        image = renderer.render()
        ti.sync()
        totals.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    out["sim_ms"] = 1e3 * statistics.median(sim_s[1:] or sim_s)
    out["sim_cpu_ms"] = 1e3 * statistics.median(sim_cpu[1:] or sim_cpu)
    out["render_ms"] = 1e3 * statistics.median(totals)
    out["render_cpu_ms"] = 1e3 * statistics.median(cpu)
    for key, seconds in renderer.timings.items():
        out["pass." + key] = 1e3 * seconds / args.frames
    with tempfile.TemporaryDirectory() as folder:
        png = []
        for k in range(args.frames):
            t0 = time.perf_counter()
            tcloth.write_png(os.path.join(folder, f"{k}.png"), image)
            png.append(time.perf_counter() - t0)
        out["png_ms"] = 1e3 * statistics.median(png)
        stats = tcloth.record(sim, os.path.join(folder, "clip.mp4"), frames=args.record,
                              steps_per_frame=steps, fps=cfg["fps"], progress=False, **options)
    out["h264_ms"] = stats["median_encode_ms"]
    out["record_sim_ms"] = stats["median_sim_ms"]
    out["record_render_ms"] = stats["median_render_ms"]
    out["fps_end_to_end"] = stats["fps"]
    return out


def child_arguments(args):
    return ["--frames", str(args.frames), "--record", str(args.record), "--settle",
            str(args.settle), "--width", str(args.width), "--height", str(args.height),
            "--supersample", str(args.supersample), "--arch", args.arch]


def run_child(python, name, args):
    """{metric: value} of scene ``name`` measured by ``python`` running this file."""
    run = subprocess.run([python, os.path.abspath(__file__), "--scenes", name]
                         + child_arguments(args), capture_output=True, text=True)
    if run.returncode:
        raise RuntimeError(f"{python} on {name} failed:\n{run.stderr[-3000:]}")
    values = {}
    for line in run.stdout.splitlines():
        key, _, value = line.partition(": ")
        if key.startswith(f"render_bench.{name}."):
            values[key[len(f"render_bench.{name}."):]] = float(value)
    return values


def against(args):
    """Both trees, every scene, in turn (module docstring)."""
    pythons = {"this": sys.executable, "other": args.against}
    results = {}
    for _ in range(args.rounds):
        for name in args.scenes.split(","):
            for tree, python in pythons.items():
                for key, value in run_child(python, name, args).items():
                    results.setdefault((name, tree, key), []).append(value)
                print(f"render_bench.{name}.done_{tree}: 1", flush=True)
    median = {k: statistics.median(v) for k, v in results.items()}
    rows = []
    for name in args.scenes.split(","):
        for key in sorted({k for (n, _, k) in median if n == name}):
            both = [median.get((name, tree, key)) for tree in pythons]
            for tree, value in zip(pythons, both):
                if value is not None:
                    print(f"render_bench.{name}.{tree}.{key}: {value:.2f}")
            if None not in both and both[1]:
                print(f"render_bench.{name}.ratio.{key}: {both[0] / both[1]:.3f}")
        rows.append("| " + " | ".join([name] + [
            " / ".join(f"{median.get((name, tree, key), float('nan')):.1f}"
                       for tree in ("other", "this")) for key in SHOWN]) + " |")
    print("\n| scene (other / this) | " + " | ".join(SHOWN) + " |")
    print("|---" * (len(SHOWN) + 1) + "|")
    print("\n".join(rows))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=",".join(scene_names()))
    ap.add_argument("--frames", type=int, default=10, help="renders of the settled state")
    ap.add_argument("--record", type=int, default=20, help="frames recorded to an MP4")
    ap.add_argument("--settle", type=int, default=10, help="frames simulated first")
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--supersample", type=int, default=2)
    ap.add_argument("--arch", default="cpu")
    ap.add_argument("--against", help="another tree's Python, to compare with")
    ap.add_argument("--rounds", type=int, default=1)
    args = ap.parse_args(argv)
    if args.against:
        against(args)
        return
    for name in args.scenes.split(","):
        for key, value in measure(name, args).items():
            print(f"render_bench.{name}.{key}: {value:.2f}")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
