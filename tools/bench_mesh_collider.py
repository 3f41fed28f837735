"""The cost of a mesh collider, side by side with the analytic sphere of the same size.

A 64 x 64 cloth (1.2 m square, 0.2 kg, springs 400 / 80 / 10 N/m, none pinned) falls flat
from y = 1 onto a sphere of radius 0.35 centred at (0, 0.35, 0) and drapes over it, at one
step per frame (dt = 1/60) with projective dynamics, for ``--seconds`` of simulated time:
once on the analytic sphere (``add_sphere``), then on geodesic sphere meshes of about
10,000 and 100,000 triangles (``tcloth.testing.meshes.sphere_mesh``, which the Newton peer
builds too), the same scene otherwise, in one run. Per case: the median ms a step (the first
step, which compiles, left out), the ratio to the analytic sphere's, the broad phase's share
(the obstacle pairs' searches: their median wall time a step over the median step's; a
search that compiles kernels for a longer list is an outlier either way), the obstacle pairs
and searches, and at the end the NumPy counts of cloth-against-obstacle crossings and of
particles inside (``tools/crossings.py``) and the cloth's lowest height.

With ``--newton-python PATH`` (a Python with ``newton``: tools/newton_mesh_peer.py), the same
drape in Newton's SolverVBD on the CPU, on the same meshes: its median ms a step and its
crossings and particles inside at the end and at the worst step.

Lines: ``mesh_collider.<case>.ms_per_step``, ``.ratio``, ``.search_share``, ``.pairs``,
``.searches``, ``.crossings_end``, ``.inside_end``, ``.lowest_m``; ``mesh_collider.newton.<n>.*``;
<out>/mesh_collider.csv.

Usage: python tools/bench_mesh_collider.py [--triangles 10000,100000] [--seconds 1]
                                           [--integrator projective] [--out docs]
                                           [--newton-python /work/newtonvenv/bin/python]
"""
import argparse
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

import tcloth
from benchcsv import write_csv
from tcloth.testing.crossings import count_inside, count_obstacle_crossings
from tcloth.testing.meshes import sphere_mesh

HERE = os.path.dirname(os.path.abspath(__file__))
RADIUS, CENTRE = 0.35, (0.0, 0.35, 0.0)


def scene(triangles):
    """The drape on the analytic sphere (triangles 0) or on a sphere mesh."""
    s = tcloth.Scene(gravity=(0.0, -9.81, 0.0))
    cloth = s.add_cloth(resolution=(64, 64), size=(1.2, 1.2), center=(0.0, 1.0, 0.0),
                        plane="xz", mass=0.2, structural=(400.0, 0.05), shear=(80.0, 0.02),
                        flexion=(10.0, 0.005), pinned=[])
    if triangles:
        v, f = sphere_mesh(RADIUS, triangles, CENTRE)
        s.add_mesh_collider((v, f))
    else:
        s.add_sphere(CENTRE, RADIUS)
    return s, cloth


def run(triangles, integrator, seconds):
    """dict of one case's figures."""
    s, cloth = scene(triangles)
    sim = tcloth.Simulator(s, integrator, dt=1.0 / 60.0)
    times, searching = [], []
    for k in range(int(round(seconds * 60))):
        before = sim.contact_stats().get("obstacle_search_seconds", 0.0)
        start = time.perf_counter()
        sim.step(1)
        times.append(time.perf_counter() - start)
        searching.append(sim.contact_stats().get("obstacle_search_seconds", 0.0) - before)
    x = sim.positions().astype(np.float64)
    stats = sim.contact_stats()
    out = {"ms_per_step": 1e3 * float(np.median(times[1:])), "lowest_m": float(x[:, 1].min()),
           "contacts": stats["collider"]}
    if triangles:
        v, f = sphere_mesh(RADIUS, triangles, CENTRE)
        out.update(triangles=len(f), pairs=stats["obstacle_pairs"],
                   searches=stats["obstacle_searches"],
                   search_share=float(np.median(searching[1:]) / np.median(times[1:])),
                   crossings_end=count_obstacle_crossings(x, cloth.triangles, v, f),
                   inside_end=count_inside(x, v, f))
    return out


def newton(python, triangles, seconds):
    """Newton's figures on the same drape (tools/newton_mesh_peer.py)."""
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "newton.npz")
        subprocess.run([python, os.path.join(HERE, "newton_mesh_peer.py"), "--triangles",
                        str(triangles), "--steps", str(int(round(seconds * 60))), "--dt",
                        repr(1.0 / 60.0), "--trajectory", "--out", path], check=True)
        data = np.load(path)
        x, tris = data["positions"].astype(np.float64), data["triangles"]
        v, f = data["obstacle_vertices"], data["obstacle_triangles"]
        worst = [(count_obstacle_crossings(p, tris, v, f), count_inside(p, v, f))
                 for p in data["trajectory"]]
        return {"ms_per_step": 1e3 * float(np.median(data["step_times"])),
                "crossings_end": count_obstacle_crossings(x, tris, v, f),
                "inside_end": count_inside(x, v, f),
                "crossings_worst": max(c for c, _ in worst),
                "inside_worst": max(i for _, i in worst)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--triangles", default="10000,100000")
    ap.add_argument("--seconds", type=float, default=1.0)
    ap.add_argument("--integrator", default="projective")
    ap.add_argument("--out", default=None)
    ap.add_argument("--newton-python", default=None)
    args = ap.parse_args(argv)
    tcloth.init("cpu")
    counts = [int(t) for t in args.triangles.split(",")]
    rows = []
    base = run(0, args.integrator, args.seconds)
    results = {"analytic": base}
    for n in counts:
        results[f"mesh_{n}"] = run(n, args.integrator, args.seconds)
        results[f"mesh_{n}"]["ratio"] = results[f"mesh_{n}"]["ms_per_step"] / base["ms_per_step"]
    if args.newton_python:
        for n in counts:
            results[f"newton_{n}"] = newton(args.newton_python, n, args.seconds)
    for case, figures in results.items():
        for key, value in figures.items():
            print(f"mesh_collider.{case}.{key}: {value:.6g}")
            rows.append({"case": case, "figure": key, "value": value})
    if args.out:
        write_csv(os.path.join(args.out, "mesh_collider.csv"), rows)
    sys.stdout.flush()


if __name__ == "__main__":
    main()
