"""The cost of self-collision, side by side with the same substep without it.

A cloth folded onto itself (scenes/fold.py, run at 40 x 40 until it has folded, then
resampled bilinearly to n x n) is stepped with symplectic Euler from that state twice in
one run: with self-collision and without (the same scene otherwise). dt is scaled with
the spacing (1.5e-4 s x 40 / n, and at most half the bound 2 m / sum k_d that the
springs' damping sets) so that every size is stable, the contact thickness too
(6 mm x 40 / n, about a quarter of the spacing: a thickness above sqrt(2) spacings would
put a flat cloth's own neighbours in contact), and the resampled state settles for
``--settle`` seconds of simulated time (0.04 s; at least 200 steps) before the timing.
The folded 40 x 40 state is read from ``--state`` (tools/data/fold_40x40.npz) where that
file exists and computed and written there otherwise: the fold is chaotic, so a change of
rounding anywhere in the physics gives another fold with other contacts, and a saved state
keeps the workload the same from one commit to the next.
Per size it prints the median ms per substep of each over chunks of 100 substeps, their
ratio, the cost per particle and how often the candidate list was rebuilt.

Next to it, the particle-particle neighbour search of warp-lang's ``HashGrid`` (build the
grid and count every particle's neighbours within the same reach, thickness + skin, in a
Warp kernel, on the same positions): the part of a self-contact step that it can match.
It has no triangles, edges, exclusion rule or forces, so it bounds from below what a
broad phase costs rather than matching tcloth's whole step.

Lines: ``self_collision.<n>x<n>.{off,on}.ms_per_substep``, ``.ratio``,
``.ns_per_particle``, ``.rebuilds_per_100``, ``.warp_hashgrid_cpu.ms``; <out>/self_collision.csv.

--implicit backward_euler,projective instead runs one simulated second of the same fold
at one step per frame (--dt 1/60), self-collision on and off, with the worst crossing count
over every step: ``self_collision.<n>x<n>.<integrator>.{on,off}_wall_s``, ``.ratio``,
``.{on,off}_mean_height_m`` (the particles' mean height at the end), ``.crossings_max``,
``.stage_*`` (the contact stage's statistics).

Usage: python tools/bench_self_collision.py [--sizes 64,128,256,512] [--steps 600]
                                            [--settle 0.04] [--skin M]
                                            [--arch cpu|cuda] [--out docs]
                                            [--state tools/data/fold_40x40.npz]
"""
import argparse
import os
import time

import numpy as np

import tcloth
from tcloth.app.script import load_script
from benchcsv import integrator_spec, write_csv
from tcloth.testing.folding import fold_scene, folded_state, one_second, resample

HERE = os.path.dirname(os.path.abspath(__file__))
# a particle's springs' k_d in scenes/fold.py: 4 structural, 4 shear, 4 flexion
DAMPING_SUM = 4 * (0.05 + 0.02 + 0.005)
# substeps per timed chunk: long enough to hold several rebuilds of the candidate list. At
# about 7 rebuilds per 100 substeps a chunk of 20 held one or two, and the median over
# chunks took one or the other (5.69 against 4.70 ms a substep at 128 x 128, same tree)
CHUNK = 100


def time_steps(sim, steps, chunk=CHUNK):
    """(median ms per substep over chunks of ``chunk`` substeps, the substeps stepped in
    all, the first chunk's, which compiles, included)."""
    sim.step(chunk)                                     # compile and warm up
    times = []
    for _ in range(max(steps // chunk, 1)):
        t = time.perf_counter()
        sim.step(chunk)
        sim.positions()                                 # wait for the device
        times.append((time.perf_counter() - t) / chunk * 1e3)
    return float(np.median(times)), (len(times) + 1) * chunk


def warp_hashgrid_ms(x, reach, repeats=5):
    """Median ms of building a warp HashGrid over x and counting neighbours within reach."""
    import warp as wp
    wp.config.quiet = True
    wp.init()

    @wp.kernel
    def count(grid: wp.uint64, pts: wp.array(dtype=wp.vec3), r: float,
              out: wp.array(dtype=int)):
        tid = wp.tid()
        i = wp.hash_grid_point_id(grid, tid)
        p = pts[i]
        n = int(0)
        for j in wp.hash_grid_query(grid, p, r):
            if wp.length(p - pts[j]) <= r and j != i:
                n += 1
        out[i] = n

    pts = wp.array(x.astype(np.float32), dtype=wp.vec3, device="cpu")
    out = wp.zeros(len(x), dtype=int, device="cpu")
    grid = wp.HashGrid(128, 128, 128, device="cpu")
    times = []
    for _ in range(repeats + 1):
        t = time.perf_counter()
        grid.build(pts, reach)
        wp.launch(count, dim=len(x), inputs=[grid.id, pts, reach, out], device="cpu")
        wp.synchronize()
        times.append((time.perf_counter() - t) * 1e3)
    return float(np.median(times[1:]))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="64,128,256")
    ap.add_argument("--steps", type=int, default=600)
    ap.add_argument("--arch", default="cpu")
    ap.add_argument("--out", default="docs")
    ap.add_argument("--no-warp", action="store_true")
    ap.add_argument("--settle", type=float, default=0.04,
                    help="simulated seconds stepped before the timing (the resampled state "
                         "rings at first)")
    ap.add_argument("--skin", type=float, default=None,
                    help="the broad phase's skin, m (default: the scene's)")
    ap.add_argument("--state", default=os.path.join(HERE, "data", "fold_40x40.npz"),
                    help="the folded 40 x 40 state: read if it exists, else written")
    ap.add_argument("--implicit", default=None,
                    help="instead: one simulated second at one step per frame with these "
                         "integrators, e.g. backward_euler,projective")
    ap.add_argument("--dt", default="1/60", help="--implicit's step, s")
    ap.add_argument("--seconds", type=float, default=1.0, help="--implicit's span, s")
    ap.add_argument("--precision", default="f32")
    args = ap.parse_args()
    tcloth.init(arch=args.arch, precision=args.precision)
    module = load_script(os.path.join(HERE, "..", "scenes", "fold.py"))[0]
    x40, v40 = folded_state(module, args.state)
    if args.implicit:
        for spec in args.implicit.split(","):
            integrator, options, label = integrator_spec(spec)
            for n in (int(s) for s in args.sizes.split(",")):
                result = one_second(module, x40, v40, n, integrator, eval(args.dt, {}),
                                    args.seconds, options)
                for key, value in result.items():
                    print(f"self_collision.{n}x{n}.{label}.{key}: {value:.6g}")
        return
    rows = []
    for n in (int(s) for s in args.sizes.split(",")):
        x, v = resample(x40, n), resample(v40, n)
        # the springs' axial damping bounds explicit steps at dt < 2 m / sum k_d
        dt = min(1.5e-4 * 40 / n, 0.5 * 2.0 * (0.2 / n ** 2) / DAMPING_SUM)
        result = {"size": n, "particles": n * n, "dt": dt}
        for mode in ("off", "on"):
            scene = fold_scene(module, n)
            if mode == "off":
                scene.self_collision = None
            elif args.skin is not None:
                scene.self_collision["skin"] = args.skin
            sim = tcloth.Simulator(scene, dt=dt)
            sim.set_state(positions=x, velocities=v)
            sim.step(max(200, int(round(args.settle / dt))))
            if mode == "on":
                broad = sim.contact.broad
                first = broad.rebuilds
            ms, stepped = time_steps(sim, args.steps)
            result[f"{mode}_ms_per_substep"] = ms
            if mode == "on":
                result["rebuilds_per_100"] = 100.0 * (broad.rebuilds - first) / stepped
                result["candidates"] = broad.count
                result["contacts"] = sum(sim.self_contacts().values())
                settings = sim.model.self_collision.settings
                reach = settings["thickness"] + settings["skin"]
        result["ratio"] = result["on_ms_per_substep"] / result["off_ms_per_substep"]
        result["ns_per_particle"] = (result["on_ms_per_substep"] - result["off_ms_per_substep"]) \
            * 1e6 / (n * n)
        if not args.no_warp:
            result["warp_hashgrid_cpu_ms"] = warp_hashgrid_ms(x, reach)
        rows.append(result)
        for key, value in result.items():
            if key != "size":
                print(f"self_collision.{n}x{n}.{key}: {value:.6g}")
    write_csv(os.path.join(args.out, f"self_collision_{args.arch}.csv"), rows)


if __name__ == "__main__":
    main()
