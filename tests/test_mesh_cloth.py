"""Cloth from any mesh: the OBJ reader, the springs and masses a mesh gives, and the
physics on a mesh cloth against closed forms and add_cloth."""
import numpy as np
import pytest

import tcloth
from tcloth import SceneError
from tcloth.geometry import primitives
from tcloth.render.mesh import cloth_mesh
from tcloth.scene.builders import fan, mesh_springs


FORMS = """# every accepted line form
mtllib cloth.mtl
o panel
g front
s off
v 0 0 0
v 1 0 0
v 1 1 0 1.0
v 0 1 0
vt 0 0
vn 0 0 1
usemtl red
f 1 2 3
f 1/1 3/1 4/1
f 1/1/1 2/1/1 3/1/1 4/1/1
f 1//1 2//1 3//1
f -4 -3 -1
l 1 2
"""


def write(tmp_path, text, name="mesh.obj"):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def test_obj_reader_takes_every_accepted_line_form(tmp_path):
    vertices, faces = tcloth.load_obj(write(tmp_path, FORMS))
    np.testing.assert_array_equal(vertices, [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    assert faces == [(0, 1, 2), (0, 2, 3), (0, 1, 2, 3), (0, 1, 2), (0, 1, 3)]


@pytest.mark.parametrize("line,what", [
    ("f 1 2 9", "out of range"), ("f 1 2 0", "out of range"), ("f 1 2 -9", "out of range"),
    ("f 1 2", "at least 3"), ("v 1 x 2", "not a number"), ("v 1 2", "3 coordinates"),
    ("f 1 a 2", "not an integer"), ("q 1 2 3", "unknown statement"),
    ("v 1 nan 2", "not finite")])
def test_malformed_obj_names_the_file_and_line(tmp_path, line, what):
    path = write(tmp_path, "v 0 0 0\nv 1 0 0\n# comment\nv 0 1 0\n" + line + "\nf 1 2 3\n")
    with pytest.raises(SceneError, match=rf"mesh\.obj:5: .*{what}"):
        tcloth.load_obj(path)


def test_missing_and_faceless_obj_files(tmp_path):
    with pytest.raises(SceneError, match="cannot read OBJ file"):
        tcloth.load_obj(str(tmp_path / "nothing.obj"))
    with pytest.raises(SceneError, match="no faces"):
        tcloth.load_obj(write(tmp_path, "v 0 0 0\n"))


def test_export_then_load_round_trips_the_deformed_cloth(f32, tmp_path):
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(6, 5), pinned=[(0, 0)])
    sim = tcloth.Simulator(scene, dt=1e-3)
    sim.step(50)
    vertices, faces = cloth_mesh(sim)
    path = str(tmp_path / "cloth.obj")
    tcloth.export_mesh(sim, path)
    v2, f2 = tcloth.load_obj(path)
    np.testing.assert_array_equal(v2, vertices)
    np.testing.assert_array_equal(np.asarray(f2), faces)
    again = tcloth.Scene()
    cloth = again.add_mesh_cloth(path)
    np.testing.assert_array_equal(again.positions, vertices)
    assert len(cloth.triangles) == len(faces)


def test_springs_of_a_hand_made_mesh():
    """Two triangles and a quad in a strip:

        3 --- 4 --- 5        faces (0 1 3), (1 4 3), (1 2 5 4)
        |   / |     |        edges: 0-1 0-3 1-3 1-4 3-4 1-2 2-5 4-5  = 8 structural
        | /   |     |        quad diagonals 1-5, 2-4                 = 2 shear
        0 --- 1 --- 2        interior edges 1-3 (opposite 0 and 4), 1-4 (opposite 3 and
                             the quad's fan triangle (1 2 5)... -> 5): flexion 0-4, 3-5
    """
    faces = [(0, 1, 3), (1, 4, 3), (1, 2, 5, 4)]
    tris, owner = fan(faces)
    np.testing.assert_array_equal(owner, [0, 1, 2, 2])
    springs = mesh_springs(faces, tris)
    assert {tuple(p) for p in springs["structural"]} == {
        (0, 1), (0, 3), (1, 3), (1, 4), (3, 4), (1, 2), (2, 5), (4, 5)}
    assert {tuple(p) for p in springs["shear"]} == {(1, 5), (2, 4)}
    assert {tuple(p) for p in springs["flexion"]} == {(0, 4), (3, 5)}


def test_mesh_errors_name_the_face_or_edge():
    x = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [2, 2, 2.0]])
    scene = tcloth.Scene()
    with pytest.raises(SceneError, match="not manifold"):
        scene.add_mesh_cloth(x, [(0, 1, 2), (0, 1, 3), (0, 1, 4)])
    with pytest.raises(SceneError, match=r"faces\[0\].*degenerate"):
        scene.add_mesh_cloth(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]]), [(0, 1, 2)])
    with pytest.raises(SceneError, match="vertex 4 is in no face"):
        scene.add_mesh_cloth(x, [(0, 1, 2), (0, 2, 3)])
    with pytest.raises(SceneError, match=r"faces\[1\].*repeats"):
        scene.add_mesh_cloth(x, [(0, 1, 2), (0, 2, 2)])
    with pytest.raises(SceneError, match="pinned"):
        scene.add_mesh_cloth(x[:3], [(0, 1, 2)], pinned=[7])
    with pytest.raises(SceneError, match=r"faces\[2\].*degenerate"):      # a seam's faces
        scene.add_mesh_cloth(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 1, 0], [1, 1, 0.]]),
                             [(0, 1, 2), (1, 4, 3), (2, 1, 3)])
    assert scene.num_particles == 0


def quad_grid(n=6):
    """add_cloth's n x n grid and the same grid as quads in its particle order."""
    scene = tcloth.Scene()
    cloth = scene.add_cloth(resolution=(n, n), size=(1, 1), plane="xz", mass=0.2,
                            structural=(400.0, 0.05), shear=(80.0, 0.02), flexion=None,
                            pinned=[(0, 0), (n - 1, 0)])
    p = cloth.particles
    faces = [(p[j, i], p[j + 1, i], p[j + 1, i + 1], p[j, i + 1])
             for j in range(n - 1) for i in range(n - 1)]
    return scene, cloth, faces


def spring_set(scene):
    sp = scene.springs
    return {(tuple(sorted(p)), k, round(float(r), 12)) for p, k, r in
            zip(sp["pairs"].tolist(), sp["kind"].tolist(), sp["rest_length"])}


def test_quad_grid_mesh_has_add_cloths_springs_and_moves_like_it(f64):
    grid, cloth, faces = quad_grid()
    mesh = tcloth.Scene()
    mc = mesh.add_mesh_cloth(grid.positions, faces, mass=0.2, structural=(400.0, 0.05),
                             shear=(80.0, 0.02), flexion=None,
                             pinned=[cloth.particles[0, 0], cloth.particles[0, -1]])
    assert spring_set(mesh) == spring_set(grid)
    # mass by vertex area: an interior vertex carries 4 quarters of a cell, a corner one
    m = mesh.masses.reshape(6, 6)
    np.testing.assert_allclose(m[2, 2] / m[0, 0], 4.0)
    np.testing.assert_allclose(mesh.masses.sum(), 0.2)
    # with add_cloth's masses (even) given per vertex: add_cloth's motion
    even = tcloth.Scene()
    even.add_mesh_cloth(grid.positions, faces, mass=grid.masses, structural=(400.0, 0.05),
                        shear=(80.0, 0.02), flexion=None,
                        pinned=[cloth.particles[0, 0], cloth.particles[0, -1]])
    runs = []
    for scene in (even, grid):
        sim = tcloth.Simulator(scene, dt=1e-3)
        sim.step(400)
        runs.append(sim.positions())
    # the same forces summed in another order (spring list against grid stencil)
    np.testing.assert_allclose(runs[0], runs[1], atol=1e-8)
    assert len(mc.triangles) == 2 * 25


def test_wind_on_a_face_on_triangle_is_drag_area_u_abs_u_in_thirds(f64):
    x = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.0, 0.0, 0.2]])
    scene = tcloth.Scene(gravity=(0, 0, 0))
    scene.add_mesh_cloth(x, [(0, 2, 1)], mass=0.3, structural=(100.0, 0.0), flexion=None)
    scene.set_wind(velocity=(0, 4.0, 0), drag=0.6)
    f = tcloth.Simulator(scene).forces()
    area = 0.5 * 0.3 * 0.2
    np.testing.assert_allclose(f, np.tile([0, 0.6 * area * 16.0 / 3, 0], (3, 1)), atol=1e-12)


def disc(rings=6, radius=0.4):
    """The tablecloth scene's irregular disc mesh: rings of 6 k vertices, finer outwards."""
    return primitives.disc(rings, radius, grading=0.8)


def test_hanging_mesh_cloth_reaches_equilibrium_where_springs_balance_gravity(f64):
    x, faces = disc(rings=4)
    x = x[:, [0, 2, 1]] + [0, 1.0, 0]                   # vertical
    top = np.argsort(x[:, 1])[-3:]
    scene = tcloth.Scene(air_drag=0.02)
    scene.add_mesh_cloth(x, faces, mass=0.1, structural=(200.0, 0.5), flexion=(5.0, 0.1),
                         pinned=top)
    sim = tcloth.Simulator(scene, "backward_euler", dt=0.02)
    sim.step(300)
    free = ~scene.pinned
    residual = np.abs(sim.forces()[free]).max()
    weight = scene.masses.max() * 9.81
    assert residual < 1e-4 * weight
    assert sim.positions()[free, 1].min() < x[free, 1].min()     # it sagged


def test_free_mesh_cloth_conserves_linear_momentum(f64):
    x, faces = disc()
    rng = np.random.default_rng(3)
    scene = tcloth.Scene(gravity=(0, 0, 0))
    scene.add_mesh_cloth(x, faces, mass=0.2, structural=(300.0, 0.1), flexion=(10.0, 0.01))
    sim = tcloth.Simulator(scene, dt=5e-4)
    sim.set_state(velocities=rng.normal(size=x.shape))
    p0 = sim.momentum()[0]
    sim.step(400)
    np.testing.assert_allclose(sim.momentum()[0], p0, atol=1e-12)


@pytest.mark.slow
def test_mesh_cloth_checkpoint_render_and_self_collision(f32, tmp_path):
    x, faces = disc()
    scene = tcloth.Scene()
    scene.add_mesh_cloth(x + [0, 0.3, 0], faces, mass=0.2, structural=(300.0, 0.1),
                         flexion=(10.0, 0.01))
    scene.add_sphere((0, 0.1, 0), 0.15, friction=0.3)
    scene.set_self_collision(thickness=0.01)
    sim = tcloth.Simulator(scene, dt=5e-4)
    sim.step(200)
    sim.save(tmp_path / "mesh.npz")
    loaded = tcloth.Simulator.load(tmp_path / "mesh.npz")
    np.testing.assert_array_equal(loaded.scene.cloths[0].triangles, scene.cloths[0].triangles)
    img = tcloth.render(loaded, 160, 120)
    assert (np.abs(img.astype(int) - tcloth.render(sim, 160, 120)).max()) == 0


@pytest.mark.slow_cases(
    "backward_euler-0.008333333333333333",
    "projective-0.008333333333333333",
    "forward_euler-5e-05",
    "rk4-0.0005",
)
@pytest.mark.parametrize("integrator,dt", [
    ("forward_euler", 5e-5), ("symplectic_euler", 2e-4), ("verlet", 2e-4), ("rk4", 5e-4),
    ("backward_euler", 1 / 120), ("projective", 1 / 120)])
def test_every_integrator_drapes_a_mesh_cloth_over_a_cylinder(f32, integrator, dt):
    """A small irregular disc with wind and strain limiting dropped on a cylinder: every
    integrator runs it through the general (spring list) paths, and it ends resting on
    the top (within the contact thickness) and hanging over the rim."""
    x, faces = disc(rings=4, radius=0.3)
    scene = tcloth.Scene(air_drag=0.01)
    scene.add_mesh_cloth(x + [0, 0.45, 0], faces, mass=0.1, structural=(200.0, 0.2),
                         flexion=(2.0, 0.01))
    scene.add_cylinder((0, 0.2, 0), 0.15, 0.2, friction=0.5, thickness=0.01)
    scene.set_wind((0.5, 0, 0), drag=0.3)
    scene.limit_strain(0.1, kinds=("structural",))
    sim = tcloth.Simulator(scene, integrator, dt=dt)
    sim.step(int(round(0.8 / dt)))
    y = sim.positions()[:, 1]
    assert y[0] == pytest.approx(0.41, abs=0.015)        # the centre rests on the top
    assert y.min() < 0.3                                  # the rim hangs over the edge
    assert sim.max_strain() < 0.11
