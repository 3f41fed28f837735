"""Every shipped scene at its CONFIG, simulation only: wall time per simulated second, the
contact stage's share, kernels compiled after the first frame, and crossings counted.

For each scene script (scenes/*.py, or ``--scenes a,b``) the simulator its CONFIG makes
(integrator, dt, options, steps a frame, frames) is stepped frame by frame with nothing
else (no rendering); the first frame, which compiles the kernels, is timed apart. Per
scene:

  build_s, first_frame_s: the simulator's construction (a mesh field's bake included)
      and its first frame;
  wall_per_sim_s: the other frames' wall time over their simulated time (1 = real time),
      stalls (kernels compiled after the first frame) included;
  falling_per_sim_s: the median frame's wall time over a frame's simulated time, of the
      frames before any particle touches a collider;
  resting_per_sim_s: the same of the last half of the frames;
  contact_share: the contact stage's time (``contact_stats()["seconds"]``) over the wall
      time of those frames;
  compiles_after_first: Taichi kernels compiled after the first frame, in the steps
      (``tcloth.runtime.compilations``; each a stall), and stalled_frames: the frames
      after the first that compiled any (docs/contact.md, "Compile once");
  inside: the most particles inside a closed mesh collider (``crossings.inside_mask``)
      or an analytic sphere, plane or box at a frame's end;
  paths_through: particle paths through a rigid mesh collider over the frames, each
      frame's path taken in the mesh's own frame (a straight segment there), summed;
  edge_crossings: the most cloth edges through mesh triangles plus mesh edges through
      cloth triangles at a frame's end (``crossings.count_obstacle_crossings``);
  self_crossings: the most cloth edges through cloth triangles at a frame's end, in a
      scene with self-collision (``crossings.count_crossings``; an edge and a triangle
      sewn together at a seam touch there by construction: ``crossings.seam_ids``);
  edge_depth_mm: at the last frame, how deep the cloth's edges reach inside a closed
      mesh collider (``crossings.edge_depth``);
  mesh<k>_field, mesh<k>_nodes, mesh<k>_bake_s: whether mesh collider k is a distance
      field (1) or on the certified pairs (0), its field's nodes and bake time
      (``contact_stats()["mesh_paths"]``).

Lines: ``scenes.<scene>.<figure>: <value>``; with --out DIR, DIR/scenes.csv.

With ``--trees A,B`` the same scenes run with the tcloth package of each work tree in
turn (A then B, ``--repeats`` times, each scene in a process of its own with that tree
first on the import path; this folder's tools measure both), and each figure is the
median over the repeats: ``scenes.<scene>.<tree>.<figure>: <value>``, tree the folder's
name (before/after on one loaded machine: the trees alternate, so a change of load falls
on both).

With ``--config KEY=VALUE`` (repeatable) every scene runs with that CONFIG key replaced,
e.g. ``--scenes fold --config integrator=projective --config dt=1/60`` (how a scene's
docstring compares its defaults with another integrator).

Usage: python tools/bench_scenes.py [--scenes table,turntable] [--frames N] [--out DIR]
                                    [--trees /work/main,. --repeats 3] [--config KEY=VALUE]
"""
import argparse
import glob
import json
import os
import re
import subprocess
import sys
import time
from fractions import Fraction
from types import SimpleNamespace

import numpy as np

import tcloth
from tcloth.app.script import (DEFAULTS, build_scene, literal, load_script, timing,
                               with_options)
from tcloth.scene.meshcollider import world_vertices
from tcloth.scene.scene import KIND_CODE
from benchcsv import write_csv
from tcloth.testing.colliders import paths_through, signed_distances
from tcloth.testing.crossings import (count_crossings, count_obstacle_crossings, edge_depth,
                                      inside_mask, seam_ids, triangle_edges)

HERE = os.path.dirname(os.path.abspath(__file__))
SCENES = os.path.join(HERE, "..", "scenes")
ANALYTIC = ("sphere", "plane", "box")        # the shapes ``signed_distances`` knows


def crossings(scene, x0, x1, t0, t1, triangles):
    """dict of one frame's counts (module docstring) at its end x1, t1."""
    out = {"inside": 0, "paths_through": 0, "edge_crossings": 0}
    for c in scene.colliders:
        if c["kind"] != "mesh":
            continue
        world = world_vertices(c, t1)
        if c["closed"]:
            out["inside"] += int(inside_mask(x1, world, c["faces"]).sum())
        if c["deform"] is None:
            out["paths_through"] += paths_through(c, x0, x1, t0, t1)
        out["edge_crossings"] += count_obstacle_crossings(x1, triangles, world, c["faces"])
    analytic = [k for k, c in enumerate(scene.colliders) if c["kind"] in ANALYTIC]
    if analytic:
        shapes = SimpleNamespace(colliders=[scene.colliders[k] for k in analytic])
        out["inside"] += int((signed_distances(shapes, x1, t1) < 0.0).any(axis=1).sum())
    if scene.self_collision is not None:
        springs = scene.springs
        seams = springs["pairs"][springs["kind"] == KIND_CODE["seam"]]
        out["self_crossings"] = count_crossings(x1, triangles,
                                                same=seam_ids(seams, scene.num_particles))
    return out


def run(path, frames, config=None):
    """The figures of one scene script (module docstring), its CONFIG updated with
    ``config`` (a dict of CONFIG keys) where given, as the command line's options update
    it (``with_options``: a dt without steps_per_frame fills a frame with its steps)."""
    module, cfg = load_script(path)
    cfg = with_options(cfg, path, {key: (f"--config {key}", value)
                                   for key, value in (config or {}).items()})
    tcloth.init("cpu", cfg["precision"])
    scene = build_scene(module, path)
    dt, steps = timing(cfg, scene)
    frames = frames or cfg["frames"]
    start = time.perf_counter()
    sim = tcloth.Simulator(scene, cfg["integrator"], dt=dt, **cfg["options"])
    figures = {"build_s": time.perf_counter() - start}
    wall, stage, touching, counts = [], [], [], []
    x, t = sim.positions().astype(np.float64), sim.time
    compiles = stalled = 0
    for frame in range(frames):
        seconds = sim.contact_stats().get("seconds", 0.0)
        before = tcloth.runtime.compilations()
        start = time.perf_counter()
        sim.step(steps)
        wall.append(time.perf_counter() - start)
        if frame > 0 and before is not None:
            compiles += tcloth.runtime.compilations() - before
            stalled += tcloth.runtime.compilations() > before
        stats = sim.contact_stats()
        stage.append(stats.get("seconds", 0.0) - seconds)
        touching.append(stats.get("collider", 0))
        x1, t1 = sim.positions().astype(np.float64), sim.time
        counts.append(crossings(scene, x, x1, t, t1, scene.triangles))
        x, t = x1, t1
    frame_s = steps * dt
    wall, stage = np.array(wall), np.array(stage)
    rest = wall[1:]
    figures.update(first_frame_s=wall[0], wall_per_sim_s=rest.sum() / (len(rest) * frame_s),
                   resting_per_sim_s=np.median(wall[frames // 2:]) / frame_s,
                   contact_share=stage[1:].sum() / max(rest.sum(), 1e-30),
                   compiles_after_first=compiles, stalled_frames=stalled)
    first_touch = next((k for k, n in enumerate(touching) if n), len(touching))
    if first_touch > 1:
        figures["falling_per_sim_s"] = np.median(wall[1:first_touch]) / frame_s
    for key in ("inside", "edge_crossings", "self_crossings"):
        if key in counts[0]:
            figures[key] = max(c[key] for c in counts)
    figures["paths_through"] = sum(c["paths_through"] for c in counts)
    closed = [c for c in scene.colliders if c["kind"] == "mesh" and c["closed"]]
    if closed:
        edges = triangle_edges(scene.triangles)
        figures["edge_depth_mm"] = 1e3 * max(edge_depth(x, edges, world_vertices(c, t),
                                                        c["faces"]) for c in closed)
    for k, path in enumerate(sim.contact_stats().get("mesh_paths", ())):
        figures.update({f"mesh{k}_field": float(path["path"] == "sdf"),
                        f"mesh{k}_nodes": path["nodes"], f"mesh{k}_bake_s": path["bake_seconds"]})
    return figures


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default=None, help="names, comma-separated (default: all)")
    ap.add_argument("--frames", type=int, default=None, help="frames (default: CONFIG's)")
    ap.add_argument("--out", default=None)
    ap.add_argument("--trees", default=None,
                    help="work trees whose tcloth to run in turn, comma-separated")
    ap.add_argument("--repeats", type=int, default=1, help="runs of each tree (--trees)")
    ap.add_argument("--config", action="append", default=[], metavar="KEY=VALUE",
                    help="a CONFIG key replaced for every scene, VALUE a Python literal "
                         "(e.g. --config integrator=xpbd --config dt=1/30; repeatable)")
    ap.add_argument("--json", action="store_true", help=argparse.SUPPRESS)   # --trees' child
    args = ap.parse_args(argv)
    config = parse_config(args.config)
    names = (args.scenes.split(",") if args.scenes else
             sorted(os.path.splitext(os.path.basename(p))[0]
                    for p in glob.glob(os.path.join(SCENES, "*.py"))))
    rows = []
    for name in names:
        path = os.path.join(SCENES, name + ".py")
        if args.trees:
            results = side_by_side(name, args.trees.split(","), args.repeats, args.frames,
                                   args.config)
        else:
            results = {None: run(path, args.frames, config)}
        if args.json:
            print(json.dumps(results[None]))
            return
        for tree, figures in results.items():
            label = name if tree is None else f"{name}.{tree}"
            for key, value in figures.items():
                print(f"scenes.{label}.{key}: {value:.6g}")
                rows.append({"scene": name, "tree": tree or "", "figure": key,
                             "value": value})
        sys.stdout.flush()
    if args.out:
        write_csv(os.path.join(args.out, "scenes.csv"), rows)


def parse_config(items):
    """{CONFIG key: value} from ``--config KEY=VALUE`` items: VALUE a fraction such as
    1/30, else as ``--set`` reads it (``script.literal``: a Python literal, or else a
    string such as xpbd); an item with no known KEY is refused with its text."""
    config = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or key not in DEFAULTS:
            raise SystemExit(f"--config {item!r}: expected KEY=VALUE with KEY one of "
                             f"{', '.join(DEFAULTS)}")
        config[key] = (float(Fraction(text)) if re.fullmatch(r"\d+/[1-9]\d*", text)
                       else literal(text))
    return config


def side_by_side(name, trees, repeats, frames, config_items=()):
    """{tree's folder name: {figure: median over ``repeats``}} of scene ``name`` run with
    each tree's tcloth in turn (module docstring)."""
    runs = {os.path.basename(os.path.abspath(tree)): [] for tree in trees}
    for _ in range(repeats):
        for tree in trees:
            env = {**os.environ, "PYTHONPATH": os.path.abspath(tree)}
            command = [sys.executable, os.path.abspath(__file__), "--scenes", name, "--json"]
            if frames:
                command += ["--frames", str(frames)]
            command += [f"--config={item}" for item in config_items]
            out = subprocess.run(command, env=env, check=True, capture_output=True,
                                 text=True).stdout
            runs[os.path.basename(os.path.abspath(tree))].append(
                json.loads(out.strip().splitlines()[-1]))
    return {tree: {key: float(np.median([r[key] for r in done if key in r]))
                   for key in dict.fromkeys(k for r in done for k in r)}
            for tree, done in runs.items()}


if __name__ == "__main__":
    main()
