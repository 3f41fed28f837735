"""Mesh colliders (``Scene.add_mesh_collider``, docs/mesh_colliders.md), against
independent references: a brute-force NumPy distance, the analytic sphere and box on the
same drape, Coulomb's bound on a slope, and the NumPy counts of cloth-against-obstacle
crossings and of particles inside (``tcloth.testing.crossings``) after every step of a cloth
thrown at 10 m/s, for every integrator."""
import os
import sys
import warnings

import numpy as np
import pytest
import taichi as ti

import tcloth
from tcloth.contact.obstacle import _flat
from tcloth.errors import SceneError
from tcloth.geometry.primitives import icosphere
from tcloth.model.collider_table import ColliderTable
from tcloth.scene.meshcollider import world_vertices
from tcloth.sim.checkpoint import scene_to_arrays

from tcloth.testing.crossings import closest_on_triangles, inside_mask
from tcloth.testing.thrown_mesh import CLOTH, OBSTACLES, box_mesh, thrown

from support.kernels import collider_contacts

HERE = os.path.dirname(os.path.abspath(__file__))


@pytest.mark.slow_cases("True")
@pytest.mark.parametrize("closed", [True, False])
def test_distance_normal_and_surface_velocity_match_a_brute_force(f64, closed):
    """A turned, moving and spinning mesh (a closed sphere, or its open upper half) at
    t = 0.3 s, queried exactly (sdf=False; its field: tests/test_mesh_fields.py): phi is
    the distance to the nearest triangle (brute force over all of them),
    negative exactly for the points inside the closed one (ray parity), the normal points
    from the closest point to x (into the outside), and the surface's velocity there is
    the finite difference of that material point's motion."""
    v, f = icosphere(0.4, 2)
    if not closed:
        f = f[v[f].mean(axis=1)[:, 1] > 0.0]
        used, f = np.unique(f, return_inverse=True)
        v, f = v[used], f.reshape(-1, 3)
    scene = tcloth.Scene()
    rot = tcloth.scene.meshcollider.rotation_about(np.array([0.6, 0.0, 0.8]), 0.7)
    c = scene.add_mesh_collider((v, f), position=(0.1, 0.2, -0.1), rotation=rot,
                                velocity=(0.3, -0.2, 0.1), angular_velocity=(0.0, 2.0, 1.0),
                                sdf=False)
    assert c["closed"] == closed
    table = ColliderTable(scene.colliders)
    t = 0.3
    world = world_vertices(c, t)
    rng = np.random.default_rng(3)
    x = world.mean(axis=0) + rng.uniform(-0.55, 0.55, (300, 3))
    out = np.zeros((len(x), 7))
    collider_contacts(table, 0, x, t, out)
    a, b, cc = (world[c["faces"][:, k]] for k in range(3))
    inside = inside_mask(x, world, c["faces"]) if closed else np.zeros(len(x), bool)
    near = 0
    for k, p in enumerate(x):
        points, d = closest_on_triangles(p, a, b, cc)
        if d.min() > c["reach"] - 1e-9:
            assert out[k, 0] == pytest.approx(c["reach"])
            continue
        near += 1
        j = np.argmin(d)
        sign = -1.0 if inside[k] else 1.0
        assert out[k, 0] == pytest.approx(sign * d[j], abs=1e-9)
        assert np.allclose(out[k, 1:4], sign * (p - points[j]) / d[j], atol=1e-6)
        own = (np.linalg.inv(_pose(c, t)[1]) @ (points[j] - _pose(c, t)[0]))
        h = 1e-6
        moved = [_pose(c, s)[1] @ own + _pose(c, s)[0] for s in (t - h, t + h)]
        assert np.allclose(out[k, 4:7], (moved[1] - moved[0]) / (2 * h), atol=1e-6)
    assert near > 100


def test_two_deforming_meshes_each_answer_their_own_surface_after_a_step(f64):
    """Two deforming closed meshes (the second's vertices stored after the first's) swell
    over a step (``ColliderTable.advance``): at the step's end each point's phi is the
    brute-force distance to the nearest of the two swollen meshes, negative inside."""
    v, f = icosphere(0.3, 2)
    scene = tcloth.Scene()
    centres = ((-0.5, 0.0, 0.0), (0.5, 0.1, 0.0))
    for k, centre in enumerate(centres):
        scene.add_mesh_collider((v, f), position=centre, sdf=False,
                                deform=lambda t, k=k: v * (1.0 + (0.2 + 0.1 * k) * t))
    table = ColliderTable(scene.colliders)
    t0, dt = 0.5, 0.25
    table.advance(t0, dt)
    rng = np.random.default_rng(5)
    x = np.concatenate([np.asarray(c) + rng.uniform(-0.45, 0.45, (150, 3)) for c in centres])
    out = np.zeros((len(x), len(centres)))
    for k in range(len(centres)):
        one = np.zeros((len(x), 7))
        collider_contacts(table, k, x, t0 + dt, one)
        out[:, k] = one[:, 0]
    for k, c in enumerate(scene.colliders):
        world = world_vertices(c, t0 + dt)
        a, b, cc = (world[f[:, j]] for j in range(3))
        inside = inside_mask(x, world, f)
        for p, phi, ins in zip(x, out[:, k], inside):
            d = closest_on_triangles(p, a, b, cc)[1].min()
            if d < c["reach"] - 1e-9:
                assert phi == pytest.approx(-d if ins else d, abs=1e-9)


def _pose(c, t):
    """(centre, rotation) of a rigid mesh collider at t, from its world vertices."""
    own = c["vertices"]
    world = world_vertices(c, t)
    a = np.c_[own, np.ones(len(own))]
    m, *_ = np.linalg.lstsq(a, world, rcond=None)
    return m[3], m[:3].T


@ti.kernel
def _ray_hits(table: ti.template(), o: ti.types.ndarray(), d: ti.types.ndarray(),
              out: ti.types.ndarray()):
    for k in range(out.shape[0]):
        for g in ti.static(table.groups):
            out[k] = table.ray_hit(g.shape, table.data[g.first], ti.Vector(
                [o[k, 0], o[k, 1], o[k, 2]]), ti.Vector([d[k, 0], d[k, 1], d[k, 2]]), 0.0)


def test_ray_hit_is_the_first_triangle_a_ray_meets(f64):
    """The renderer's ray hit on a turned mesh: the nearest positive Moller-Trumbore hit
    over every triangle (NumPy brute force), or -1 where the ray misses them all."""
    v, f = icosphere(0.3, 2)
    scene = tcloth.Scene()
    c = scene.add_mesh_collider((v, f), position=(0.0, 0.5, 0.0), scale=(1.0, 0.5, 1.5))
    table = ColliderTable(scene.colliders)
    world = world_vertices(c, 0.0)
    rng = np.random.default_rng(4)
    o = rng.normal(size=(200, 3)) * 2.0
    d = rng.uniform(-0.5, 0.5, (200, 3)) + (0.0, 0.5, 0.0) - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    out = np.zeros(200)
    _ray_hits(table, o, d, out)
    a, b, cc = (world[c["faces"][:, k]] for k in range(3))
    hits = 0
    for k in range(200):
        e1, e2 = b - a, cc - a
        pv = np.cross(d[k], e2)
        det = np.einsum("ij,ij->i", e1, pv)
        tv = o[k] - a
        u = np.einsum("ij,ij->i", tv, pv) / det
        qv = np.cross(tv, e1)
        w = (qv @ d[k]) / det
        s = np.einsum("ij,ij->i", e2, qv) / det
        ok = (u >= 0) & (w >= 0) & (u + w <= 1) & (s > 0)
        if ok.any():
            hits += 1
            assert out[k] == pytest.approx(s[ok].min(), rel=1e-6)
        else:
            assert out[k] == -1.0
    assert 20 < hits < 200


def drape(collider, mesh):
    """A 12 x 12 cloth of 0.24 m laid on top of a sphere of radius 0.25 or of a box, held by
    projective dynamics at one step per frame for 1 s (it takes the sphere's cap without
    folding, so its rest shape is unique): the positions. The meshes keep the certified
    pairs (sdf=False; their fields drape in tests/test_mesh_fields.py)."""
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0), air_damping=2.0)
    scene.add_cloth(resolution=(12, 12), size=(0.24, 0.24), center=(0.0, 0.51, 0.0),
                    mass=0.05, plane="xz", **CLOTH)
    if collider == "sphere":
        if mesh:
            v, f = icosphere(0.25, 4)
            scene.add_mesh_collider((v, f), position=(0.0, 0.25, 0.0), friction=0.5,
                                    sdf=False)
        else:
            scene.add_sphere((0.0, 0.25, 0.0), 0.25, friction=0.5)
    elif mesh:
        scene.add_mesh_collider(box_mesh(np.array([0.2, 0.1, 0.2])), position=(0, 0.1, 0),
                                friction=0.5, sdf=False)
    else:
        scene.add_box((0.0, 0.1, 0.0), (0.2, 0.1, 0.2), friction=0.5)
    sim = tcloth.Simulator(scene, "projective", dt=1.0 / 60.0)
    sim.step(60)
    return sim.positions().astype(np.float64)


@pytest.mark.slow
@pytest.mark.parametrize("collider", ["sphere", "box"])
def test_a_mesh_drape_rests_as_the_analytic_shape_s(f32, collider):
    """The same drape on a finely tessellated sphere (5120 faces) and on the analytic
    sphere, on a box mesh and on the analytic box: the rest shapes agree within a tenth of
    the tessellation's chord error (the largest gap between its faces and the sphere)
    plus the thickness."""
    chord = 0.0
    if collider == "sphere":
        v, f = icosphere(0.25, 4)
        chord = 0.25 - np.linalg.norm(v[f].mean(axis=1), axis=1).min()
    gap = np.abs(drape(collider, True) - drape(collider, False)).max()
    assert gap <= 0.1 * chord + 0.005, (gap, chord)


@pytest.mark.slow
def test_a_particle_on_a_sloped_mesh_obeys_coulomb_s_bound(f64):
    """A particle resting on a mesh slope (two triangles) of 20 degrees, friction 0.5,
    sticks (tan 20 < 0.5: it creeps at most at the friction's regularisation speed), and
    one on a slope of 35 degrees slides with g (sin - mu cos), as on the analytic plane:
    both in one scene, 0.3 s of symplectic Euler."""
    mu, eps, dt = 0.5, 5e-3, 5e-4                 # eps > mu g dt / 2 (colliders.py)
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0))
    square = np.array([[-1.0, 0, -1.0], [1.0, 0, -1.0], [1.0, 0, 1.0], [-1.0, 0, 1.0]])
    slopes = []
    for k, angle in enumerate((20.0, 35.0)):
        theta = np.radians(angle)
        rot = tcloth.scene.meshcollider.rotation_about(np.array([0.0, 0.0, 1.0]), theta)
        place = np.array([0.0, 0.0, 3.0 * k])
        scene.add_mesh_collider((square, [(0, 3, 2, 1)]), position=place, rotation=rot,
                                friction=mu, stiffness=1000.0, stick_velocity=eps)
        normal = rot @ np.array([0.0, 1.0, 0.0])
        start = place + (0.005 - 0.01 * 9.81 * np.cos(theta) / 1000.0) * normal   # at rest
        scene.add_particles(start[None], mass=0.01)
        slopes.append((theta, start, rot @ np.array([-1.0, 0.0, 0.0])))   # down the slope
    sim = tcloth.Simulator(scene, "symplectic_euler", dt=dt)
    sim.step(600)
    for p, (theta, start, down) in enumerate(slopes):
        slid = float((sim.positions()[p] - start) @ down)
        if np.tan(theta) < mu:
            assert abs(slid) < 2.0 * eps * np.tan(theta) / mu * 0.3, slid
        else:
            expected = 0.5 * 9.81 * (np.sin(theta) - mu * np.cos(theta)) * 0.3 ** 2
            assert slid == pytest.approx(expected, rel=0.03)


# the frame-rate solvers, each on one of the plate and the still, spinning and breathing
# sphere (the explicit integrators' contact paths: test_contact.py); each case compiles a
# simulator (40-120 s on two cores): the slow set. ``tools/thrown_mesh.py`` runs every
# integrator on every obstacle.
FRAME_RATE = ("backward_euler", "projective", "vbd", "xpbd")
CASES = [pytest.param(integrator, *OBSTACLES[k], marks=pytest.mark.slow)
         for k, integrator in enumerate(FRAME_RATE)]


@pytest.mark.parametrize("integrator,collider,motion", CASES)
def test_a_thrown_cloth_never_enters_or_crosses_a_mesh(fresh_f32, integrator, collider,
                                                        motion):
    """A cloth thrown down at 10 m/s onto a mesh plate 1 cm thick or a mesh sphere (still,
    spinning or breathing): after every step no particle is inside the obstacle and no
    cloth edge crosses an obstacle triangle nor an obstacle edge a cloth triangle (NumPy
    counts), nothing blows up, and the cloth reached it: the frame-rate solvers at 1/60 s,
    the explicit ones at their own dt (``tools/thrown_mesh.py``, which runs the matrix at
    any dt)."""
    r = thrown(integrator, collider, motion)         # tcloth.testing.thrown_mesh
    assert r["error"] is None, r["error"]
    assert r["crossings"] == 0 and r["inside"] == 0, r
    assert r["closest"] < 0.05, r                   # it reached the obstacle


@pytest.mark.slow
def test_a_checkpoint_stores_the_mesh_and_continues_bit_for_bit(f32, tmp_path):
    """A cloth on a keyframed mesh and beside a breathing one (frames as an array): saved
    after 30 steps (the mesh by content: the OBJ it came from is deleted before loading)
    and continued 30 steps, it equals the uninterrupted run bit for bit; the stage's
    statistics count its searches; a callable deform cannot be stored, and saving
    says so."""
    obj = tmp_path / "plate.obj"
    v, quads = box_mesh(np.array([0.2, 0.01, 0.2]))
    obj.write_text("".join(f"v {a} {b} {c}\n" for a, b, c in v)
                   + "".join("f " + " ".join(str(i + 1) for i in q) + "\n" for q in quads))

    def build(deform):
        scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0))
        scene.add_cloth(resolution=(8, 8), size=(0.3, 0.3), center=(0.0, 0.013, 0.0),
                        mass=0.05, plane="xz", **CLOTH)
        turn = tcloth.scene.meshcollider.rotation_about(np.array([0.0, 1.0, 0.0]), 0.4)
        scene.add_mesh_collider(str(obj), friction=0.4, keyframes=[
            (0.0, (0.0, 0.0, 0.0), np.eye(3)), (0.5, (0.05, 0.02, 0.0), turn)])
        s, f = icosphere(0.05, 1)
        scene.add_mesh_collider((s, f), position=(0.4, 0.0, 0.0), deform=deform,
                                deform_fps=10.0)
        return scene

    s, _ = icosphere(0.05, 1)
    with pytest.raises(SceneError, match="callable"):
        scene_to_arrays(build(lambda t: s))
    frames = np.stack([s * (1.0 + 0.1 * k) for k in range(4)])
    whole = tcloth.Simulator(build(frames), "symplectic_euler", dt=5e-4)
    whole.step(30)
    path = tmp_path / "run.npz"
    whole.save(path)
    whole.step(30)
    obj.unlink()
    again = tcloth.Simulator.load(path)
    again.step(30)
    assert np.array_equal(again.positions(), whole.positions())
    assert np.array_equal(again.velocities(), whole.velocities())
    stats = whole.contact_stats()
    assert stats["obstacle_searches"] > 0


@pytest.mark.slow
def test_bad_meshes_are_refused_with_the_file_face_or_vertex_named(f32, tmp_path):
    """Each bad input raises one SceneError naming what is wrong; a mesh wound
    inconsistently is taken as open, with a warning."""
    scene = tcloth.Scene()
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 0, 1], [1, 0, 1]])
    cases = [
        (str(tmp_path / "gone.obj"), "gone.obj"),
        ((v, [(0, 1, 7)]), r"faces\[0\].*outside"),
        ((v, [(0, 1, 2), (0, 1, 1)]), r"faces\[1\].*repeats"),
        ((np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]), [(0, 1, 2)]), "degenerate"),
        ((np.array([[0.0, 0, 0], [1, 0, np.nan], [0, 0, 1]]), [(0, 1, 2)]), r"\[1,2\]"),
        ((v, []), "no face|in no face"),
    ]
    for mesh, message in cases:
        with pytest.raises(SceneError, match=message):
            scene.add_mesh_collider(mesh)
    empty = tmp_path / "empty.obj"
    empty.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    with pytest.raises(SceneError, match="empty.obj.*no faces"):
        scene.add_mesh_collider(str(empty))
    with pytest.raises(SceneError, match="one motion"):
        scene.add_mesh_collider((v, [(0, 1, 3, 2)]), velocity=(1, 0, 0), keyframes=[
            (0.0, (0, 0, 0), None)])
    with pytest.raises(SceneError, match=r"\(frames, 4, 3\)"):
        scene.add_mesh_collider((v, [(0, 1, 3, 2)]), deform=np.zeros((2, 3, 3)))
    with pytest.raises(SceneError, match=r"deform\(0.0\).*vertex count"):
        scene.add_mesh_collider((v, [(0, 1, 3, 2)]), deform=lambda t: v[:3])
    with pytest.raises(SceneError, match="keyframes"):
        scene.add_mesh_collider((v, [(0, 1, 3, 2)]), keyframes=[(1.0, (0, 0, 0), None),
                                                               (0.5, (0, 0, 0), None)])
    tet = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    with pytest.warns(UserWarning, match="taken as open"):
        c = tcloth.Scene().add_mesh_collider((tet, [(0, 2, 1), (0, 1, 3), (1, 2, 3),
                                                    (0, 2, 3)]))
    assert c["closed"] is False
    ball, faces = icosphere(0.3, 1)
    crossing = tcloth.Scene()
    crossing.add_mesh_collider((np.concatenate([ball, ball + (0.2, 0.0, 0.0)]),
                                np.concatenate([faces, faces + len(ball)])))
    with pytest.warns(UserWarning, match="crosses itself"):
        table = ColliderTable(crossing.colliders)
    out = np.zeros((1, 7))
    collider_contacts(table, 0, np.array([[0.1, 0.0, 0.0]]), 0.0, out)     # inside both: unsigned
    assert out[0, 0] > 0.0


@pytest.mark.slow
def test_a_deforming_mesh_whose_vertex_count_changes_is_refused_at_that_frame(f32):
    """A callable deform that returns fewer vertices at a later frame: the step that asks
    for that frame raises one SceneError naming the call and the vertex count (it runs
    a simulator: the slow set)."""
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 0, 1], [1, 0, 1]])
    scene = tcloth.Scene()
    changing = scene.add_mesh_collider((v, [(0, 1, 3, 2)]),
                                       deform=lambda t: v if t < 0.01 else v[:3])
    scene.add_particles([[0.5, 0.5, 0.5]])
    sim = tcloth.Simulator(scene, "symplectic_euler", dt=5e-3)
    with pytest.raises(SceneError, match=r"deform\(0.01.*vertex count"):
        sim.step(4)
    assert changing["closed"] is False


@pytest.mark.slow
def test_faces_in_one_plane_are_no_self_crossing(f32):
    """A closed solid of revolution whose flat rings lie in one plane (scenes/turntable.py's
    turntable: its foot's underside and its platter's top are fans and annuli in a plane)
    is closed, not crossing itself: in float32 an edge in a face's plane used to meet it
    by rounding."""
    sys.path.insert(0, os.path.join(HERE, "..", "scenes"))
    import turntable
    scene = tcloth.Scene()
    c = scene.add_mesh_collider(turntable.lathe(turntable.supported(turntable.PROFILE)))
    assert c["closed"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        table = ColliderTable(scene.colliders)
    out = np.zeros((1, 7))
    collider_contacts(table, 0, np.array([[0.0, 0.2, 0.0]]), 0.0, out)     # in the column: inside
    assert out[0, 0] < 0.0


def test_flat_patches_are_found_by_their_faces_normals():
    """``_flat`` against hand counts: a box's six face diagonals are its only flat edges
    and it has no flat vertex; a sphere has neither; a flat 3 x 3 grid of quads (two
    triangles each) has 21 interior edges, each flat and listed by both its faces, and 4
    interior vertices; bending the grid along x = 1 unflattens that line's edges and
    vertices only."""
    v, quads = box_mesh(np.array([0.5, 0.1, 0.3]))
    q = np.asarray(quads)
    flat_v, flat_e = _flat(v, np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]]))
    assert flat_e.sum() == 12 and not flat_v.any()
    flat_v, flat_e = _flat(*icosphere(0.2, 2))
    assert not flat_v.any() and not flat_e.any()
    g = np.array([[i, 0.0, j] for j in range(4) for i in range(4)], dtype=float)
    tris = np.array([t for j in range(3) for i in range(3) for t in
                     ([j * 4 + i, j * 4 + i + 4, j * 4 + i + 1],
                      [j * 4 + i + 1, j * 4 + i + 4, j * 4 + i + 5])])
    flat_v, flat_e = _flat(g, tris)
    assert flat_e.sum() == 2 * 21
    assert sorted(set(tris[flat_v])) == [5, 6, 9, 10]
    g[:, 1] = 0.1 * np.maximum(g[:, 0] - 1.0, 0.0)      # bent along x = 1
    flat_v, flat_e = _flat(g, tris)
    assert sorted(set(tris[flat_v])) == [6, 10]
    assert flat_e.sum() == 2 * 21 - 2 * 3           # the crease's three edges


@pytest.mark.slow
def test_a_cloth_landing_on_a_platter_with_a_rim_gains_no_energy(fresh_f32):
    """Projective dynamics drops a cloth onto scenes/turntable.py's turntable, standing
    still, its corners past the platter's rim: contact is inelastic, so the total energy
    (kinetic, gravitational, springs', contact's) never rises above its start. The guard's
    planes once moved only the particles that touched and held 4.6 J in the springs
    pulled over the rim (the energy budget stopped the run); the solver now pulls the
    cloth onto them (``Projective._hold``)."""
    sys.path.insert(0, os.path.join(HERE, "..", "scenes"))
    import turntable
    sim = tcloth.Simulator(turntable.build(spin=0.0), "projective", dt=1.0 / 60.0)
    start = sim.energy()["total"]
    most = -np.inf
    for _ in range(20):         # it lands in step 10
        sim.step(1)
        most = max(most, sim.energy()["total"])
    assert most <= start + 1e-6 * abs(start), (most, start)
    assert sim.positions()[:, 1].min() > 0.3        # on the platter, not through it
