"""The mesh colliders' stress set: a cloth thrown down at 10 m/s onto a mesh plate 1 cm
thick or a mesh sphere (still, spinning or breathing), every integrator, with the NumPy
counts of crossings and particles inside (``crossings``) after every step.

``thrown(integrator, collider, motion, dt=None, sdf=False)`` runs one case and returns what
it found (tools/thrown_mesh.py runs the matrix at a dt of one's choosing).
"""
import warnings

import numpy as np

import tcloth
from tcloth.errors import InstabilityError
from tcloth.geometry.primitives import icosphere
from tcloth.scene.meshcollider import world_vertices

from .colliders import paths_through
from .contact_cases import CLOTH
from .crossings import count_obstacle_crossings, inside_mask

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
    blows up landing on the analytic box too, ``contact_cases.falling``), the
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
