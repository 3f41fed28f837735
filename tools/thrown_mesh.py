"""The mesh colliders' stress set: a cloth thrown down at 10 m/s onto a mesh plate 1 cm
thick or a mesh sphere (still, spinning or breathing), every integrator, with the NumPy
counts of crossings and particles inside (``crossings.py``) after every step.

``thrown(integrator, collider, motion, dt=None, sdf=False)`` runs one case and returns what
it found; ``tests/test_mesh_collider.py`` asserts on every case at 1/60 s and the
integrators' own dt (``tests/test_mesh_fields.py`` on some with sdf="auto"). As a tool it
runs the matrix at a dt of your choosing (the issue's guarantee holds up to 1/30 s) and
prints one line a case, as the benchmarks print their figures:

    python tools/thrown_mesh.py --dt 1/30 [--integrators projective,vbd] [--colliders plate]
                                [--sdf]

    thrown.<integrator>.<collider>[.<motion>]: crossings <n> inside <n> paths <n> closest <m>
        steps <n> (<path>, <n> fallbacks, <s> s) [error]

(--sdf: the obstacles as distance fields where they can be, ``add_mesh_collider``'s
sdf="auto"; by default the certified pairs, whose guarantee the crossings count.)
"""
import argparse
import os
import sys
import time
import warnings
from fractions import Fraction

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

import tcloth  # noqa: E402
from tcloth.errors import InstabilityError  # noqa: E402
from tcloth.geometry.primitives import icosphere  # noqa: E402
from tcloth.scene.meshcollider import world_vertices  # noqa: E402
from crossings import count_obstacle_crossings, inside_mask  # noqa: E402
from bench_scenes import paths_through  # noqa: E402

CLOTH = {"structural": (400.0, 0.05), "shear": (80.0, 0.02), "flexion": (10.0, 0.005),
         "pinned": []}
OWN_DT = {"forward_euler": 2e-5, "symplectic_euler": 1e-4, "verlet": 1e-4, "rk4": 2e-4}
INTEGRATORS = ("forward_euler", "symplectic_euler", "verlet", "rk4", "backward_euler",
               "projective", "vbd", "xpbd")
OBSTACLES = (("plate", None), ("sphere", None), ("sphere", "spin"), ("sphere", "deform"))


def box_mesh(half):
    """(8 vertices, 6 quads) of a box of half extents ``half`` about the origin."""
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)],
                       dtype=float) * half
    return corners, [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4),
                     (1, 5, 7, 3)]


def falling(collider, res, height, motion=None, self_collision=False, sdf=False):
    """A res x res cloth of 0.6 m at ``height`` falling at 10 m/s onto a mesh plate 1 cm
    thick (its top at 0.105) or a mesh sphere of radius 0.12 (1280 faces), centred at
    (0, 0.1, 0) and still, spinning about y at 2 rad/s or breathing (its radius 1 +- 0.2
    times at 12 rad/s), on the certified pairs (``sdf`` False) or as ``add_mesh_collider``'s
    ``sdf`` says; a plane below. Returns (scene, velocities, collider, cloth)."""
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0))
    cloth = scene.add_cloth(resolution=(res, res), size=(0.6, 0.6), center=(0.0, height, 0.0),
                            mass=0.2, **CLOTH)
    if collider == "plate":
        v, f = box_mesh(np.array([0.25, 0.005, 0.25]))
    else:
        v, f = icosphere(0.12, 3)
    motions = {None: {}, "spin": {"angular_velocity": (0.0, 2.0, 0.0)},
               "deform": {"deform": lambda t: v * (1.0 + 0.2 * np.sin(12.0 * t))}}
    c = scene.add_mesh_collider((v, f), position=(0.0, 0.1, 0.0), friction=0.3, sdf=sdf,
                                **motions[motion])
    scene.add_plane((0.0, -0.3, 0.0), (0.0, 1.0, 0.0), friction=0.3)
    if self_collision:
        scene.set_self_collision(thickness=0.006)
    velocities = scene.velocities
    velocities[cloth.particles.ravel(), 1] = -10.0
    return scene, velocities, c, cloth


def thrown(integrator, collider, motion=None, dt=None, sdf=False):
    """One case: the frame-rate solvers (dt above 1 ms) on a 24 x 24 cloth from 0.3 m for
    0.4 s (its triangles small beside the sphere's curvature, as a cloth must be to lie on
    it without the sphere showing through; VBD on the plate a 12 x 12 one: its 24 x 24
    blows up landing on the analytic box too, ``bench_contact.py``'s falling scene), the
    explicit ones from 4.5 cm above for 15 ms; the strain bound 2, VBD and XPBD with
    substeps "auto". ``dt``: the integrator's own (OWN_DT, else 1/60) by default; ``sdf``:
    as ``falling``'s. Returns {"crossings", "inside": the most at any step checked (every
    step at frame rate, every fifth else), "paths": particle paths through a rigid
    obstacle (in its frame) over every step, "closest": the nearest any particle came to
    an obstacle vertex, "steps" run, "error": the InstabilityError's message or None,
    "path": the obstacle's path (``contact_stats()["mesh_paths"]``: "sdf" or
    "certified"), "fallbacks": the field's queries beyond its band}."""
    dt = dt or OWN_DT.get(integrator, 1.0 / 60.0)
    frame = dt > 1e-3
    top = 0.105 if collider == "plate" else 0.22
    res = 12 if not frame or (integrator == "vbd" and collider == "plate") else 24
    scene, velocities, c, cloth = falling(collider, res, 0.3 if frame else top + 0.045,
                                          motion, sdf=sdf)
    options = {"strain_bound": 2.0}
    if integrator in ("vbd", "xpbd"):
        options["substeps"] = "auto"
    sim = tcloth.Simulator(scene, integrator, dt=dt, **options)
    sim.set_state(velocities=velocities)
    faces = np.asarray(c["faces"])
    out = {"crossings": 0, "inside": 0, "paths": 0, "closest": np.inf, "steps": 0,
           "error": None, "path": sim.contact_stats()["mesh_paths"][0]["path"]}
    x = sim.positions().astype(np.float64)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for k in range(int(round((0.4 if frame else 0.015) / dt))):
            t0 = sim.time
            try:
                sim.step(1)
            except InstabilityError as e:
                out["error"] = str(e)
                break
            out["steps"] = k + 1
            x0, x = x, sim.positions().astype(np.float64)
            if motion != "deform":
                out["paths"] += paths_through(c, x0, x, t0, sim.time)
            if not frame and k % 5:
                continue
            obstacle = world_vertices(c, sim.time)
            out["crossings"] = max(out["crossings"], count_obstacle_crossings(
                x, cloth.triangles, obstacle, faces))
            out["inside"] = max(out["inside"], int(inside_mask(x, obstacle, faces).sum()))
            out["closest"] = min(out["closest"], float(np.min(np.linalg.norm(
                x[:, None] - obstacle[None], axis=2))))
    out["fallbacks"] = sim.contact_stats()["sdf_fallbacks"]
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dt", default=None,
                        help="step (s, or a fraction such as 1/30); the integrators' own "
                             "by default")
    parser.add_argument("--integrators", default=",".join(INTEGRATORS))
    parser.add_argument("--colliders", default="plate,sphere",
                        help="plate, sphere (the sphere still, spinning and breathing)")
    parser.add_argument("--arch", default="cpu")
    parser.add_argument("--sdf", action="store_true",
                        help="the obstacles as distance fields where they can be "
                             "(sdf=\"auto\"; default: the certified pairs)")
    args = parser.parse_args(argv)
    dt = float(Fraction(args.dt)) if args.dt else None
    if dt is not None and not dt > 0:
        parser.error(f"--dt must be positive (got {args.dt!r})")
    integrators = args.integrators.split(",")
    for name in integrators:
        if name not in INTEGRATORS:
            parser.error(f"--integrators: unknown integrator {name!r} "
                         f"(one of {', '.join(INTEGRATORS)})")
    colliders = args.colliders.split(",")
    tcloth.init(args.arch)
    for integrator in integrators:
        for collider, motion in OBSTACLES:
            if collider not in colliders:
                continue
            start = time.perf_counter()
            r = thrown(integrator, collider, motion, dt, "auto" if args.sdf else False)
            name = ".".join(p for p in ("thrown", integrator, collider, motion) if p)
            print(f"{name}: crossings {r['crossings']} inside {r['inside']} paths "
                  f"{r['paths']} closest {r['closest']:.4f} steps {r['steps']} ({r['path']}, "
                  f"{r['fallbacks']} fallbacks, {time.perf_counter() - start:.0f} s)"
                  + (f" error: {r['error'][:160]}" if r["error"] else ""), flush=True)


if __name__ == "__main__":
    main()
