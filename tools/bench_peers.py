"""tcloth against the peers of warp-lang's cloth benchmark, side by side in one run.

The scene is warp.examples.benchmarks.benchmark_cloth's: an n x n cloth of 0.1 m spacing,
0.1 kg particles, the two corners of row 0 fixed, structural, shear and bend springs of
k_s = 1000 and k_d = 10, gravity 9.81, 60 frames a second with 16 semi-implicit Euler
substeps. Its ``Cloth`` builder is taken from the installed warp-lang (the class is read
out of the module, whose import would run the whole benchmark) and its spring list is
checked to equal tcloth's ``add_cloth`` list; the peers' integrators are imported from the
package. tcloth runs the same scene with ``symplectic_euler`` (the same update) and its
final positions are compared with Warp's.

Prints greppable lines ``peers.<n>x<n>.<impl>.ms_per_substep: value`` (median over
frames), ``peers.<n>x<n>.<impl>_over_warp_cpu: value`` and
``peers.<n>x<n>.max_position_difference_m: value``, and writes <out>/peers.csv.

--newton also runs Newton's (PyPI ``newton``) cloth_hanging example in its benchmark mode
for the given solvers, next to tcloth on a cloth of the same particle count, spacing and
particle mass, fixed along one edge above a ground plane, at the example's substep. The
scenes cannot be matched exactly: Newton's cloth is triangle FEM (semi_implicit, vbd) or
edge springs (xpbd) with particle-shape contacts, not Provot springs; the comparison is
cost per substep at equal size. Lines: ``peers.newton_<w>x<h>.<impl>.ms_per_substep``.

Usage: python tools/bench_peers.py [--sizes 32,64,128] [--frames 60] [--numpy-frames 2]
                                   [--newton semi_implicit,xpbd] [--newton-seconds 30]
       (needs the benchmark extra: pip install -e ".[bench]"; --newton needs newton)
"""
import argparse
import ast
import importlib.util
import os
import re
import subprocess
import sys
import time

import numpy as np

import tcloth
from benchcsv import write_csv

FPS, SUBSTEPS = 60.0, 16
K, KD, SPACING, MASS = 1000.0, 10.0, 0.1, 0.1


def warp_cloth_class():
    """warp-lang's benchmark ``Cloth`` class, without running the benchmark module."""
    path = importlib.util.find_spec("warp.examples.benchmarks.benchmark_cloth").origin
    with open(path) as f:
        tree = ast.parse(f.read(), path)
    node = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "Cloth")
    namespace = {"np": np}
    exec(compile(ast.Module(body=[node], type_ignores=[]), path, "exec"), namespace)
    return namespace["Cloth"]


def warp_cloth(n):
    return warp_cloth_class()(lower=(0.0, 0.0, 0.0), dx=n, dy=n, radius=SPACING,
                              stretch_stiffness=K, bend_stiffness=K, shear_stiffness=K,
                              mass=MASS, fix_corners=True)


def tcloth_scene(n):
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0))
    scene.add_cloth(resolution=(n, n), size=(SPACING * (n - 1),) * 2,
                    center=(SPACING * (n - 1) / 2, 0.0, SPACING * (n - 1) / 2),
                    mass=MASS * n * n, structural=(K, KD), shear=(K, KD), flexion=(K, KD))
    return scene


def check_same_scene(cloth, scene):
    """The two spring lists (unordered pairs with rest length, k_s, k_d), positions and
    inverse masses agree; raises AssertionError otherwise."""
    def spring_set(pairs, rest, ks, kd):
        return sorted((min(i, j), max(i, j), round(float(r), 5), float(k), float(d))
                      for (i, j), r, k, d in zip(pairs, rest, ks, kd))
    ours = scene.springs
    theirs = spring_set(cloth.spring_indices.reshape(-1, 2), cloth.spring_lengths,
                        cloth.spring_stiffness, cloth.spring_damping)
    assert spring_set(ours["pairs"], ours["rest_length"], ours["stiffness"],
                      ours["damping"]) == theirs, "spring lists differ"
    assert np.allclose(scene.positions, cloth.positions, atol=1e-5), "positions differ"
    inv = np.where(scene.pinned, 0.0, 1.0 / scene.masses)
    assert np.allclose(inv, cloth.inv_masses, rtol=1e-6), "inverse masses differ"


def time_frames(simulate, frames):
    """Median ms per substep over frames of SUBSTEPS substeps; returns (ms, last result)."""
    times, result = [], None
    for _ in range(frames):
        t0 = time.perf_counter()
        result = simulate()
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times)) / SUBSTEPS, result


def run_size(n, frames, numpy_frames):
    results = {}
    scene = tcloth_scene(n)
    check_same_scene(warp_cloth(n), scene)
    print(f"peers.{n}x{n}.particles: {scene.num_particles}")
    print(f"peers.{n}x{n}.springs: {scene.num_springs}", flush=True)

    # every implementation first runs one frame (compiling), then frames timed frames
    tcloth.init(arch="cpu")
    sim = tcloth.Simulator(scene, "symplectic_euler", dt=1 / (FPS * SUBSTEPS))
    sim.step(SUBSTEPS)

    def tcloth_frame():
        sim.step(SUBSTEPS)
        return sim.positions()
    results["tcloth_cpu"], x_tcloth = time_frames(tcloth_frame, frames)

    import warp as wp
    from warp.examples.benchmarks import benchmark_cloth_warp
    wp.config.quiet = True
    warp_cpu = benchmark_cloth_warp.WpIntegrator(warp_cloth(n), "cpu")
    warp_cpu.simulate(1 / FPS, SUBSTEPS)
    results["warp_cpu"], x_warp = time_frames(
        lambda: warp_cpu.simulate(1 / FPS, SUBSTEPS), frames)

    from warp.examples.benchmarks import benchmark_cloth_taichi
    taichi_peer = benchmark_cloth_taichi.TiIntegrator(warp_cloth(n), "cpu")
    taichi_peer.simulate(1 / FPS, SUBSTEPS)
    results["warp_taichi_cpu"], _ = time_frames(
        lambda: taichi_peer.simulate(1 / FPS, SUBSTEPS), frames)
    tcloth.init(arch="cpu")                  # Warp's Taichi version re-initialised Taichi

    from warp.examples.benchmarks import benchmark_cloth_numpy
    numpy_peer = benchmark_cloth_numpy.NpIntegrator(warp_cloth(n))
    results["warp_numpy"], _ = time_frames(
        lambda: numpy_peer.simulate(1 / FPS, SUBSTEPS), numpy_frames)

    key = f"peers.{n}x{n}"
    for impl, ms in results.items():
        print(f"{key}.{impl}.ms_per_substep: {ms:.4g}")
    for impl, ms in results.items():
        if impl != "warp_cpu":
            print(f"{key}.{impl}_over_warp_cpu: {ms / results['warp_cpu']:.3g}")
    travel = float(np.abs(x_warp - warp_cloth(n).positions).max())
    diff = float(np.abs(x_tcloth - x_warp).max())
    print(f"{key}.max_travel_m: {travel:.4g}")
    print(f"{key}.max_position_difference_m: {diff:.3g}", flush=True)
    return {"n": n, **results, "max_travel_m": travel, "max_position_difference_m": diff}


NEWTON_SUBSTEPS = {"semi_implicit": 32, "xpbd": 10, "vbd": 10, "style3d": 2}


def newton_peer(solvers, width, height, seconds):
    """Newton's cloth_hanging (benchmark mode) against tcloth at its size and substep."""
    rows = []
    key = f"peers.newton_{width}x{height}"
    for solver in solvers:
        res = subprocess.run(
            [sys.executable, "-m", "newton.examples", "cloth_hanging", "--viewer", "null",
             "--benchmark", str(seconds), "--num-frames", "100000", "--solver", solver,
             "--width", str(width), "--height", str(height), "--quiet"],
            capture_output=True, text=True)
        match = re.search(r"Benchmark: ([0-9.]+) FPS \((\d+) frames", res.stdout + res.stderr)
        if match is None:
            print(f"# newton {solver} failed: {(res.stdout + res.stderr)[-300:]}")
            continue
        ms = 1e3 / (float(match.group(1)) * NEWTON_SUBSTEPS[solver])
        print(f"{key}.newton_{solver}.ms_per_substep: {ms:.4g} ({match.group(2)} frames)",
              flush=True)
        rows.append({"impl": f"newton_{solver}", "ms_per_substep": ms})
    nx, ny = width + 1, height + 1
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(nx, ny), size=(SPACING * width, SPACING * height),
                    center=(0.0, 4.0, 0.0), plane="xy", mass=MASS * nx * ny,
                    structural=(K, KD), shear=(K, KD), flexion=(K, KD),
                    pinned=[(0, j) for j in range(ny)])
    scene.add_plane((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), stiffness=100.0, friction=1.0)
    tcloth.init(arch="cpu")
    for solver in solvers:
        substeps = NEWTON_SUBSTEPS[solver]
        sim = tcloth.Simulator(scene, "symplectic_euler", dt=1 / (FPS * substeps))
        sim.step(substeps)
        times = []
        for _ in range(30):
            t0 = time.perf_counter()
            sim.step(substeps)
            sim.state.x[0]
            times.append(time.perf_counter() - t0)
        ms = 1e3 * float(np.median(times)) / substeps
        print(f"{key}.tcloth_at_{solver}_substep.ms_per_substep: {ms:.4g}", flush=True)
        rows.append({"impl": f"tcloth_at_{solver}_substep", "ms_per_substep": ms})
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="32,64,128")
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--numpy-frames", type=int, default=2)
    ap.add_argument("--newton", default="")
    ap.add_argument("--newton-size", default="128x16")
    ap.add_argument("--newton-seconds", type=int, default=30)
    ap.add_argument("--out", default="docs")
    args = ap.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    if args.sizes:
        rows = [run_size(int(s), args.frames, args.numpy_frames) for s in args.sizes.split(",")]
        write_csv(os.path.join(args.out, "peers.csv"), rows)
    if args.newton:
        width, height = (int(s) for s in args.newton_size.split("x"))
        rows = newton_peer(args.newton.split(","), width, height, args.newton_seconds)
        write_csv(os.path.join(args.out, "peers_newton.csv"), rows)


if __name__ == "__main__":
    main()
