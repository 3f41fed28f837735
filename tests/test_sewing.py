"""Sewing (``Scene.sew``, ``tcloth.panel``, welds, scenes/garment.py) against closed forms
(the damped oscillator, a polygon's area) and NumPy references (the welded mesh's
neighbours, segment-triangle crossings)."""
import numpy as np
import pytest

import tcloth
from tcloth import SceneError
from tcloth.contact.topology import contact_topology
from tcloth.render.mesh import cloth_mesh

from tcloth.testing.crossings import count_crossings, seam_ids

from conftest import scene_module

SQUARE = ((0.0, 0.0), (0.2, 0.0), (0.2, 0.2), (0.0, 0.2))
CLOTH = {"mass": 0.02, "structural": (100.0, 0.02), "flexion": (1.0, 0.001), "pinned": []}


# -- one seam spring: a damped oscillator -------------------------------------------------------
def oscillator(t, r0, mu, ks, kd):
    """The separation of two particles joined by a zero-rest-length spring, released at
    rest r0 apart: mu r'' + kd r' + ks r = 0 (underdamped)."""
    w0 = np.sqrt(ks / mu)
    zeta = kd / (2.0 * np.sqrt(ks * mu))
    wd = w0 * np.sqrt(1.0 - zeta ** 2)
    return r0 * np.exp(-zeta * w0 * t) * (np.cos(wd * t) + zeta * w0 / wd * np.sin(wd * t))


@pytest.mark.slow_cases(
    "backward_euler-0.0001-0.01",
    "projective-0.0001-0.01",
    "vbd-0.0001-0.06",
)
@pytest.mark.parametrize("integrator, dt, tol", [
    ("symplectic_euler", 1e-4, 3e-3), ("rk4", 1e-3, 1e-5), ("backward_euler", 1e-4, 1e-2),
    ("projective", 1e-4, 1e-2), ("xpbd", 1e-4, 1e-2), ("vbd", 1e-4, 6e-2)])
def test_a_seam_spring_is_a_damped_oscillator(f64, integrator, dt, tol):
    """Two free particles sewn together oscillate through zero separation (where the
    spring's direction is undefined) as mu r'' = -ks r - kd r', their centre of mass at
    rest: every integrator follows the closed form, none divides by the zero length."""
    m1, m2, ks, kd, r0 = 0.01, 0.03, 4.0, 0.01, 0.05
    mu = m1 * m2 / (m1 + m2)
    scene = tcloth.Scene(gravity=(0.0, 0.0, 0.0))
    scene.add_particles([[0.0, 0.0, 0.0], [r0, 0.0, 0.0]], mass=[m1, m2])
    scene.sew([0], [1], stiffness=ks, damping=kd)
    sim = tcloth.Simulator(scene, integrator=integrator, dt=dt)
    period = 2 * np.pi / np.sqrt(ks / mu)
    errors, crossed = [], False
    for _ in range(60):
        sim.step(int(round(period / 40 / dt)))
        x = sim.positions()
        r = x[1, 0] - x[0, 0]
        crossed |= r < 0
        errors.append(abs(r - oscillator(sim.time, r0, mu, ks, kd)) / r0)
        assert np.all(np.isfinite(x)) and np.allclose(x[:, 1:], 0.0)
        assert abs(m1 * x[0, 0] + m2 * x[1, 0] - m2 * r0) < 1e-6 * (m1 + m2) * r0
    assert crossed and sim.time > 1.4 * period
    assert max(errors) < tol, max(errors)


def test_sew_refuses_bad_input():
    scene = tcloth.Scene()
    scene.add_particles(np.eye(3), mass=1.0)
    with pytest.raises(SceneError, match="one to one"):
        scene.sew([0, 1], [2], stiffness=1.0)
    with pytest.raises(SceneError, match="share particle 1"):
        scene.sew([0, 1], [1, 2], stiffness=1.0)
    with pytest.raises(SceneError, match="outside"):
        scene.sew([0], [3], stiffness=1.0)
    with pytest.raises(SceneError, match="weld must be"):
        scene.sew([0], [1], stiffness=1.0, weld="yes")
    with pytest.raises(SceneError, match="stiffness"):
        scene.sew([0], [1], stiffness=-1.0)
    with pytest.raises(SceneError, match="seam's"):
        scene.add_springs([[0, 1]], 1.0, rest_length=0.0)
    scene.sew([0], [1], stiffness=1.0, weld=True)
    with pytest.raises(SceneError, match="already in a welded seam"):
        scene.sew([1], [2], stiffness=1.0, weld=True)


# -- panels ---------------------------------------------------------------------------------
def shoelace(p):
    p = np.asarray(p, dtype=np.float64)
    return 0.5 * np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])


@pytest.mark.parametrize("outline", [SQUARE, scene_module("garment").OUTLINE,
                                     ((0.0, 0.0), (0.3, 0.0), (0.3, 0.1), (0.1, 0.1),
                                      (0.1, 0.3), (0.0, 0.3))[::-1]])
def test_a_panel_tiles_its_outline(outline):
    """Counter-clockwise triangles cover the polygon's area exactly; each outline edge's
    points run from its corner to the next on the edge, no further apart than the
    resolution; every point is in a triangle."""
    h = 0.03
    cut = tcloth.panel(outline, h)
    v, tri = cut.vertices, cut.triangles
    e1, e2 = v[tri[:, 1]] - v[tri[:, 0]], v[tri[:, 2]] - v[tri[:, 0]]
    area = 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    assert area.min() > 0.0
    assert np.isclose(area.sum(), abs(shoelace(outline)), rtol=1e-12)
    assert np.array_equal(np.unique(tri), np.arange(len(v)))
    corners = cut.outline
    assert np.isclose(shoelace(corners), abs(shoelace(outline)))
    for k, edge in enumerate(cut.edges):
        a, b = corners[k], corners[(k + 1) % len(corners)]
        assert np.allclose(v[edge[0]], a) and np.allclose(v[edge[-1]], b)
        along = v[edge] - a
        assert np.allclose(along[:, 0] * (b - a)[1] - along[:, 1] * (b - a)[0], 0.0,
                           atol=1e-12)
        steps = np.linalg.norm(np.diff(v[edge], axis=0), axis=1)
        assert steps.max() <= h * (1 + 1e-9) and np.allclose(steps, steps[0])
        edges = {tuple(sorted(e)) for t in tri for e in ((t[0], t[1]), (t[1], t[2]),
                                                         (t[2], t[0]))}
        assert all(tuple(sorted(p)) in edges for p in zip(edge[:-1], edge[1:]))


def test_panel_refuses_bad_outlines():
    with pytest.raises(SceneError, match="cross"):
        tcloth.panel(((0, 0), (2, 2), (2, 0), (0, 1)), 0.1)
    with pytest.raises(SceneError, match="resolution"):
        tcloth.panel(SQUARE, 0.0)
    with pytest.raises(SceneError, match="no area"):
        tcloth.panel(((0, 0), (1, 0), (2, 0)), 0.1)
    with pytest.raises(SceneError, match="outline must be"):
        tcloth.panel(((0, 0), (1, 0)), 0.1)


def two_panels(gap=0.1, weld=False, ks=20.0, kd=0.05, self_collision=True, air_damping=0.0):
    """Two 0.2 m squares with their bottom edges ``gap`` apart (along z), sewn there: one
    upright in the xy plane, the other leaning away from it (a V once sewn)."""
    scene = tcloth.Scene(gravity=(0.0, 0.0, 0.0), air_damping=air_damping)
    cut = tcloth.panel(SQUARE, 0.04)
    a = cut.add_to(scene, **CLOTH)
    c, s = np.cos(0.8), np.sin(0.8)
    b = cut.add_to(scene, origin=(0.0, 0.0, -gap),
                   rotation=[[1.0, 0.0, 0.0], [0.0, c, s], [0.0, -s, c]], **CLOTH)
    scene.sew(a.edges[0], b.edges[0], stiffness=ks, damping=kd, weld=weld)
    if self_collision:
        scene.set_self_collision(thickness=0.004)
    return scene, a.edges[0], b.edges[0]


def merged_triangles(scene, a, b):
    """The scene's triangles with each b[i] replaced by a[i]: the sewn mesh as one."""
    merge = np.arange(scene.num_particles)
    merge[b] = a
    return merge, merge[scene.triangles]


def test_self_contact_takes_a_seams_pair_as_one_particle():
    """The contact neighbours of a sewn pair's particles are those of one particle in the
    welded mesh (b replaced by a): no contact across the seam can hold it open."""
    scene, a, b = two_panels()
    topo = contact_topology(scene)
    merge, welded = merged_triangles(scene, a, b)
    assert np.array_equal(topo["twin"], np.minimum(np.arange(scene.num_particles), merge))

    def neighbours(start, nbrs, p):
        return set(nbrs[start[p]:start[p + 1]].tolist())
    links = np.concatenate([welded[:, [0, 1]], welded[:, [1, 2]], welded[:, [2, 0]]])
    ref = {p: set() for p in range(scene.num_particles)}
    for i, j in links:
        ref[i].add(j)
        ref[j].add(i)
    for p in range(scene.num_particles):
        got = {merge[q] for q in neighbours(topo["start"], topo["neighbours"], p)} - {merge[p]}
        assert got == ref[merge[p]] - {merge[p]}, p


def test_a_welded_seam_shares_its_particles(tmp_path):
    """Two panels sewn with weld close, each pair becomes one particle (same position and
    velocity; the merged triangles reference only a), momentum stays zero, nothing
    stretches far past its rest, and a checkpoint continues the welded run exactly."""
    scene, a, b = two_panels(weld=True, self_collision=False)
    sim = tcloth.Simulator(scene, integrator="symplectic_euler", dt=2e-4)
    assert len(sim.welded()) == 0 and np.array_equal(sim.triangles(), scene.triangles)
    sim.step(2500)                                    # 0.5 s: a few periods of the seam
    welded = sim.welded()
    assert sorted(map(tuple, welded)) == sorted(zip(a.tolist(), b.tolist()))
    x, v = sim.positions(), sim.velocities()
    assert np.array_equal(x[a], x[b]) and np.array_equal(v[a], v[b])
    tri = sim.triangles()
    assert not np.isin(b, tri).any() and np.isin(a, tri).all()
    assert len(np.unique(tri)) == scene.num_particles - len(a)
    assert np.abs(scene.masses @ v).max() < 1e-5
    assert np.all(np.isfinite(x)) and sim.max_strain() < 0.2
    vertices, faces = cloth_mesh(sim)                 # exported as one mesh
    assert len(vertices) == scene.num_particles - len(a)
    assert np.array_equal(vertices[faces], x[tri])
    path = str(tmp_path / "welded.npz")
    sim.save(path)
    sim.step(50)
    again = tcloth.Simulator.load(path)             # the welds and their seams come back
    assert np.array_equal(again.welded(), welded)
    again.step(50)
    assert np.array_equal(again.positions(), sim.positions())
    assert np.array_equal(again.welded(), sim.welded())
    sim.reset()
    assert len(sim.welded()) == 0


@pytest.mark.slow_cases("projective-0.016666666666666666")
@pytest.mark.parametrize("integrator, dt", [("symplectic_euler", 2e-4), ("projective", 1 / 60)])
def test_a_seam_closes_through_the_contact_thickness(f32, integrator, dt):
    """With self-collision on, a seam closes to a twentieth of the contact thickness in a
    second (neither the seam's neighbours' contact nor the guard holds it open), and the
    panels, sewn pairs taken as one particle, never cross."""
    scene, a, b = two_panels(gap=0.05, ks=20.0, kd=0.2, air_damping=3.0)
    sim = tcloth.Simulator(scene, integrator=integrator, dt=dt)
    steps = int(round(1 / 60 / dt))
    same = seam_ids(np.stack([a, b], 1), scene.num_particles)   # a sewn pair: one point
    for _ in range(60):                               # one second
        sim.step(steps)
        assert count_crossings(sim.positions(), scene.triangles, same=same) == 0
    x = sim.positions()
    gap = np.linalg.norm(x[a] - x[b], axis=1)
    assert gap.max() < 0.05 * scene.self_collision["thickness"], gap.max()


@pytest.mark.slow
def test_the_garment_has_no_self_crossings_at_any_frame(f32):
    """scenes/garment.py at a coarse resolution: at no frame does an edge pass through a
    triangle (``tcloth.testing.crossings``) but where they touch by construction at a seam (an
    end of one sewn to a corner of the other); every seam welds within a second, the
    welded pairs coincide, and the merged mesh has no crossing at the end."""
    module = scene_module("garment")
    scene = module.build(resolution=0.05)
    config = module.CONFIG
    sim = tcloth.Simulator(scene, integrator=config["integrator"], dt=config["dt"])
    pairs = scene.springs["pairs"][scene.springs["kind"] == 4]
    same = seam_ids(pairs, scene.num_particles)
    for frame in range(90):
        sim.step(config["steps_per_frame"])
        x = sim.positions()
        assert np.all(np.isfinite(x))
        assert count_crossings(x, scene.triangles, same=same) == 0, frame
        if frame == 60:
            assert len(sim.welded()) == len(pairs)
    assert count_crossings(x, sim.triangles()) == 0             # the merged mesh's
    welded = sim.welded()
    assert np.array_equal(x[welded[:, 0]], x[welded[:, 1]])
    assert x[:, 1].min() > module.HEM - 0.1        # hangs on the shoulders (a free
    #                                                 fall for 1.5 s drops 11 m)


def test_gradients_refuse_welded_seams():
    scene, _, _ = two_panels(weld=True, self_collision=False)
    with pytest.raises(SceneError, match="welded seams"):
        tcloth.grad.Trajectory(scene, steps=2, dt=1e-3)
