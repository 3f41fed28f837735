"""Mesh colliders as signed distance fields (``geometry/sdf.py``, docs/mesh_colliders.md),
against independent references: the brute-force NumPy distance to the mesh and ray parity,
the analytic sphere on the same drape, the closed form of a particle carried round by a
turning platter, and the NumPy counts of particles inside and of paths through the mesh
after every step of a cloth thrown at it."""
import os
import sys

import numpy as np
import pytest

import tcloth
from tcloth.errors import SceneError
from tcloth.geometry.primitives import icosphere
from tcloth.geometry.trimesh import face_normals
from tcloth.model.collider_table import ColliderTable
from tcloth.scene.meshcollider import rotation_about, world_vertices
from tcloth.sim.checkpoint import scene_from_arrays, scene_to_arrays

from tcloth.testing.crossings import closest_on_triangles, inside_mask
from tcloth.testing.thrown_mesh import CLOTH, box_mesh, thrown

from support.kernels import collider_contacts

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "scenes"))
from turntable import lathe  # noqa: E402

CELL = 0.005        # the colliders' default thickness, which is a field's cell


def _largest_dihedral(v, f):
    """The largest angle between the normals of two faces that share an edge (rad)."""
    n, _ = face_normals(v, f)
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    _, which = np.unique(edges, axis=0, return_inverse=True)
    order = np.argsort(which.ravel(), kind="stable")
    faces = np.tile(np.arange(len(f)), 3)[order]
    return float(np.arccos(np.clip((n[faces[0::2]] * n[faces[1::2]]).sum(1), -1, 1)).max())


@pytest.mark.parametrize("mesh", ["sphere", "box"])
def test_a_field_s_distance_and_normal_match_the_exact_mesh(f64, mesh):
    """A turned, moving and spinning mesh baked as a field (cell 5 mm) at t = 0.3 s, at
    random points within its band: phi is the brute-force distance to the nearest
    triangle, negative exactly for the points inside (ray parity) farther than a tenth
    of a cell from the surface, within a tenth of a cell on a sphere mesh (the trilinear
    interpolant of a smooth distance is within 3 c^2 / (8 rho) of it, rho the level
    sets' curvature radius; the facets' edges bend them more) and a quarter of one on a
    box (its edges and corners: level sets of radius d); on the sphere the normal is
    within twice the largest angle between neighbouring faces of the brute force's
    direction (across a facet's edge the exact gradient turns by that angle, and a cell
    can straddle two such turns)."""
    v, f = icosphere(0.15, 3) if mesh == "sphere" else box_mesh(np.array([0.15, 0.05, 0.1]))
    f = np.asarray(f)
    scene = tcloth.Scene()
    c = scene.add_mesh_collider((v, f), position=(0.1, 0.2, -0.1),
                                rotation=rotation_about(np.array([0.6, 0.0, 0.8]), 0.7),
                                velocity=(0.3, -0.2, 0.1), angular_velocity=(0.0, 2.0, 1.0))
    table = ColliderTable(scene.colliders)
    path = table.sdf.paths[0]
    assert path["path"] == "sdf" and path["cell"] == CELL
    t, band = 0.3, path["band"]
    world = world_vertices(c, t)
    faces = c["faces"]
    rng = np.random.default_rng(5)
    x = rng.uniform(world.min(axis=0) - band, world.max(axis=0) + band, (3000, 3))
    a, b, cc = (world[faces[:, k]] for k in range(3))
    exact, direction = np.zeros(len(x)), np.zeros((len(x), 3))
    for k in range(0, len(x), 200):
        p = x[k:k + 200]
        points, d = closest_on_triangles(p[:, None], a, b, cc)
        j = np.argmin(d, axis=1)
        rows = np.arange(len(p))
        exact[k:k + 200] = d[rows, j]
        direction[k:k + 200] = (p - points[rows, j]) / d[rows, j, None]
    inside = inside_mask(x, world, faces)
    exact[inside], direction[inside] = -exact[inside], -direction[inside]
    out = np.zeros((len(x), 7))
    collider_contacts(table, 0, x, t, out)
    near = np.abs(exact) < band
    assert near.sum() > 500
    tolerance = (0.1 if mesh == "sphere" else 0.25) * CELL
    assert np.abs(out[near, 0] - exact[near]).max() <= tolerance
    clear = near & (np.abs(exact) > 0.1 * CELL)
    assert np.array_equal(out[clear, 0] < 0.0, inside[clear])
    assert inside[near].sum() > 100 and (~inside[near]).sum() > 100
    if mesh == "sphere":
        angle = np.arccos(np.clip((out[near, 1:4] * direction[near]).sum(axis=1), -1, 1))
        assert angle.max() <= 2.0 * _largest_dihedral(v, f)
    far = ~near & ~inside
    assert np.all(out[far, 0] >= band - tolerance)     # beyond the band: the band, a bound


def test_the_automatic_choice_keeps_the_pairs_where_a_field_cannot_hold(f32):
    """sdf="auto": a closed rigid sphere becomes a field; a deforming one, an open one, a
    plate thinner than two cells (4 mm at a 5 mm cell) and one asked not to keep the
    certified pairs, each with its reason; sdf=True says why it cannot be where it
    cannot (when the scene is built, or when the thin plate is measured); a checkpoint
    keeps the choice."""
    ball, faces = icosphere(0.1, 2)
    used, cup = np.unique(faces[ball[faces].mean(axis=1)[:, 1] < 0.0], return_inverse=True)
    cup = (ball[used], cup.reshape(-1, 3))         # the lower half: open
    scene = tcloth.Scene()
    scene.add_mesh_collider((ball, faces))
    scene.add_mesh_collider((ball, faces), position=(1, 0, 0), deform=np.stack([ball, ball]))
    scene.add_mesh_collider(cup, position=(2, 0, 0))
    scene.add_mesh_collider(box_mesh(np.array([0.2, 0.002, 0.2])), position=(3, 0, 0))
    scene.add_mesh_collider((ball, faces), position=(4, 0, 0), sdf=False)
    paths = ColliderTable(scene.colliders).sdf.paths
    assert [p["path"] for p in paths] == ["sdf"] + ["certified"] * 4
    for p, why in zip(paths, ("", "deforms", "open", "thinnest part, 4.0 mm", "sdf=False")):
        assert why in p["reason"], (why, p["reason"])
    assert paths[0]["nodes"] > 0 and paths[0]["depth"] >= 2 * CELL
    with pytest.raises(SceneError, match="deforms"):
        tcloth.Scene().add_mesh_collider((ball, faces), deform=lambda t: ball, sdf=True)
    with pytest.raises(SceneError, match="open"):
        tcloth.Scene().add_mesh_collider(cup, sdf=True)
    with pytest.raises(SceneError, match="sdf must be"):
        tcloth.Scene().add_mesh_collider((ball, faces), sdf="yes")
    thin = tcloth.Scene()
    thin.add_mesh_collider(box_mesh(np.array([0.2, 0.002, 0.2])), sdf=True)
    with pytest.raises(SceneError, match="thinnest part"):
        ColliderTable(thin.colliders)
    scene.add_particles([[0.0, 1.0, 0.0]])
    again = scene_from_arrays(*scene_to_arrays(scene))
    assert [c["sdf"] for c in again.colliders] == ["auto"] * 4 + [False]


@pytest.mark.slow
@pytest.mark.parametrize("integrator,dt", [("projective", 1.0 / 60.0),
                                           ("symplectic_euler", 2e-4)])
def test_a_cloth_drapes_on_a_sphere_field_within_a_millimetre_of_the_analytic_one(
        f32, integrator, dt):
    """A 12 x 12 cloth of 0.24 m laid on a sphere of radius 0.25 (friction 0.5) for 1 s,
    once on the analytic sphere and once on a sphere mesh of 5,120 faces baked as a field:
    every particle ends within 1 mm of where it ends on the analytic one (the mesh's
    facets lie within 0.13 mm of the sphere, the field within a hundredth of a cell of
    the mesh)."""
    def drape(mesh):
        scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0), air_damping=2.0)
        scene.add_cloth(resolution=(12, 12), size=(0.24, 0.24), center=(0.0, 0.51, 0.0),
                        mass=0.05, plane="xz", **CLOTH)
        if mesh:
            scene.add_mesh_collider(icosphere(0.25, 4), position=(0.0, 0.25, 0.0),
                                    friction=0.5)
        else:
            scene.add_sphere((0.0, 0.25, 0.0), 0.25, friction=0.5)
        sim = tcloth.Simulator(scene, integrator, dt=dt)
        sim.step(int(round(1.0 / dt)))
        if mesh:
            assert sim.contact_stats()["mesh_paths"][0]["path"] == "sdf"
        return sim.positions().astype(np.float64)
    field, analytic = drape(True), drape(False)
    assert analytic[:, 1].min() < 0.49                       # it lies on the cap
    assert np.linalg.norm(field - analytic, axis=1).max() < 1e-3


@pytest.mark.slow
def test_a_turning_field_carries_a_resting_particle_round_with_its_surface(f64):
    """A particle resting on a platter (a closed disc mesh of radius 0.3, baked as a
    field) that turns at 2 rad/s, friction 0.8, moving with the surface: friction holds
    it (the centripetal pull it needs, omega^2 r = 0.8 m/s^2, is under mu g), so after
    0.5 s of symplectic Euler it is where the platter's point it sat on went (turned by
    omega t about the axis) and moves at omega x r, within twice the creep of the
    friction's regularisation (eps omega^2 r / (mu g) = 1e-4 m/s, 5e-5 m over the run;
    without friction it ends 10 cm away)."""
    omega, r, mu, dt, steps = 2.0, 0.2, 0.8, 2e-4, 2500
    disc = lathe([(0.0, 0.0), (0.3, 0.0), (0.3, 0.04), (0.0, 0.04)], sectors=48)
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0))
    scene.add_mesh_collider(disc, friction=mu, angular_velocity=(0.0, omega, 0.0))
    rest = 0.04 + 0.005 - 0.01 * 9.81 / 1000.0       # the penalty's equilibrium height
    start = np.array([r, rest, 0.0])
    scene.add_particles(start[None], mass=0.01,
                        velocities=np.cross([0.0, omega, 0.0], start)[None])
    sim = tcloth.Simulator(scene, "symplectic_euler", dt=dt)
    assert sim.contact_stats()["mesh_paths"][0]["path"] == "sdf"
    sim.step(steps)
    turned = rotation_about(np.array([0.0, 1.0, 0.0]), omega * steps * dt) @ start
    x, v = sim.positions()[0], sim.velocities()[0]
    assert np.linalg.norm(x - turned) < 1e-4, (x, turned)
    assert np.linalg.norm(v - np.cross([0.0, omega, 0.0], x)) < 2e-4, v


# a cloth thrown at 10 m/s onto a field (tools/thrown_mesh.py --sdf runs every integrator):
# no particle ends inside it or passes through it, the landing beyond its band counted;
# each case compiles a simulator of its own (23 to 39 s of CPU with none of its kernels in
# Taichi's offline cache, about 5 s with them there)
THROWN = [("projective", "plate", None), ("xpbd", "sphere", "spin"),
          ("symplectic_euler", "plate", None), ("backward_euler", "sphere", None)]


@pytest.mark.slow
@pytest.mark.parametrize("integrator,collider,motion", THROWN)
def test_a_cloth_thrown_at_a_field_never_enters_it(fresh_f32, integrator, collider, motion):
    """``thrown`` with sdf="auto" (the plate, 1 cm thick, and the sphere become fields):
    after every step no particle is inside the mesh and no particle's path over the step
    (in the mesh's frame) passes through one of its triangles (NumPy counts against the
    exact mesh); the frame-rate solvers' landing asked beyond the band, counted."""
    r = thrown(integrator, collider, motion, sdf="auto")
    assert r["error"] is None, r["error"]
    assert r["path"] == "sdf"
    assert r["inside"] == 0 and r["paths"] == 0, r
    assert r["closest"] < 0.05, r
    assert integrator == "symplectic_euler" or r["fallbacks"] > 0, r
