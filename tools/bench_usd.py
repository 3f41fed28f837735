"""What the USD export adds to a render (the target: at most 10 %): ``tcloth render SCRIPT
--frames N`` with and without ``--usd``, each a process of its own as a user runs it,
taken in turn (plain, with USD, plain, ...) so that both see the same machine. Prints
greppable lines:

    usd_bench.<case>.median_s: <wall-clock seconds of the whole command, median>
    usd_bench.<case>.runs_s: <each run>
    usd_bench.usd.median_ms_per_frame: <the USD writer's time a frame, from the render's
                                        closing line>
    usd_bench.ratio: <median with USD / median without>

Usage: python tools/bench_usd.py [--script scenes/cloth_on_sphere.py] [--frames 120]
           [--repeats 3] [--format .usdc] [--out out/bench_usd] [--set NAME=VALUE ...]
"""
import argparse
import os
import re
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))


def run(command):
    """(seconds, stderr) of one command, which must succeed."""
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if done.returncode:
        sys.exit(f"{' '.join(command)} failed ({done.returncode}): {done.stderr.strip()}")
    return seconds, done.stderr


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--script", default=os.path.join(HERE, "..", "scenes", "cloth_on_sphere.py"))
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--format", default=".usdc", choices=[".usda", ".usdc", ".usdz"])
    ap.add_argument("--out", default=os.path.join("out", "bench_usd"))
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    args = ap.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    base = [sys.executable, "-m", "tcloth", "render", args.script, "--frames",
            str(args.frames), "--out", os.path.join(args.out, "scene.mp4")]
    base += [item for setting in args.set for item in ("--set", setting)]
    cases = {"render": base,
             "render_usd": base + ["--usd", os.path.join(args.out, "scene" + args.format)]}
    run(cases["render_usd"])       # Taichi's kernel cache filled, the files in place
    times = {name: [] for name in cases}
    usd_ms = []
    for _ in range(args.repeats):
        for name, command in cases.items():
            seconds, err = run(command)
            times[name].append(seconds)
            said = re.search(r"USD ([0-9.]+) ms/frame", err)
            if said:
                usd_ms.append(float(said.group(1)))
    print(f"usd_bench.frames: {args.frames}")
    print(f"usd_bench.script: {os.path.relpath(args.script)}")
    for name, runs in times.items():
        print(f"usd_bench.{name}.median_s: {statistics.median(runs):.2f}")
        print(f"usd_bench.{name}.runs_s: {' '.join(f'{t:.2f}' for t in runs)}")
    print(f"usd_bench.usd.median_ms_per_frame: {statistics.median(usd_ms):.2f}")
    size = os.path.getsize(os.path.join(args.out, "scene" + args.format))
    print(f"usd_bench.usd.file_mb: {size / 1e6:.1f}")
    ratio = statistics.median(times["render_usd"]) / statistics.median(times["render"])
    print(f"usd_bench.ratio: {ratio:.3f}")


if __name__ == "__main__":
    main()
