"""The pressure term (``Scene.set_pressure``): its force against finite differences of its
energy, its zero net force and torque, the equilibrium of an inflated balloon against the
closed form, checkpoints and its input checks."""
import numpy as np
import pytest

import tcloth
from tcloth import SceneError

from conftest import energy_gradient


def icosahedron(radius=1.0, subdivide=False):
    """(vertices (12 or 42, 3), faces (20 or 80, 3)) wound outward."""
    g = (1 + 5 ** 0.5) / 2
    v = np.array([[-1, g, 0], [1, g, 0], [-1, -g, 0], [1, -g, 0], [0, -1, g], [0, 1, g],
                  [0, -1, -g], [0, 1, -g], [g, 0, -1], [g, 0, 1], [-g, 0, -1], [-g, 0, 1]],
                 dtype=float)
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9],
                  [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2],
                  [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
                  [8, 6, 7], [9, 8, 1]])
    if subdivide:
        mid = {}
        v = list(v)

        def middle(a, b):
            key = (min(a, b), max(a, b))
            if key not in mid:
                mid[key] = len(v)
                v.append((v[a] + v[b]) / 2)
            return mid[key]
        faces = []
        for a, b, c in f:
            ab, bc, ca = middle(a, b), middle(b, c), middle(c, a)
            faces += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        v, f = np.array(v), np.array(faces)
    return radius * v / np.linalg.norm(v, axis=1, keepdims=True), f


def balloon(x, faces, pressure, ambient, structural=None, mass=0.01, drag=0.0):
    scene = tcloth.Scene(gravity=(0, 0, 0), air_drag=drag)
    scene.add_mesh_cloth(x, faces.tolist(), mass=mass, structural=structural, flexion=None)
    scene.set_pressure(pressure, ambient=ambient)
    return scene


def test_pressure_force_is_minus_the_gradient_of_its_energy(f64):
    rng = np.random.default_rng(4)
    x, faces = icosahedron(0.2, subdivide=True)
    x += rng.normal(scale=0.01, size=x.shape)
    sim = tcloth.Simulator(balloon(x, faces, pressure=300.0, ambient=1e4))
    f = sim.forces()
    entries = [(0, 0), (7, 1), (13, 2), (41, 0)]
    grad = energy_gradient(sim, x, "pressure", entries, h=1e-7)
    for p, c in entries:
        assert f[p, c] == pytest.approx(-grad[p, c], rel=1e-6, abs=1e-9)
    # a closed surface: the pressure forces and their torques sum to zero
    assert np.abs(f.sum(axis=0)).max() < 1e-12 * np.abs(f).max() * len(f)
    assert np.abs(np.cross(x, f).sum(axis=0)).max() < 1e-12 * np.abs(f).max() * len(f)
    # the force is the net pressure times a third of the area-weighted normals at V0
    a, b, c = (x[faces[:, k]] for k in range(3))
    normals = np.cross(b - a, c - a) / 2
    expected = np.zeros_like(x)
    for k in range(3):
        np.add.at(expected, faces[:, k], 300.0 * normals / 3)
    assert np.allclose(f, expected, rtol=1e-9, atol=1e-12)


def test_inflated_balloon_rests_at_the_closed_form_radius(f64):
    """An icosahedron of springs (30 edges, k) filled with gas: by symmetry it stays a
    regular icosahedron of radius R, where the springs' pull balances the net pressure,
    30 k (a(R) - l0) a'(R) = (P0 V0 / V(R) - P_a) V'(R) (virtual work), with a = c_a R
    and V = c_v R^3; solved by bisection."""
    r0, k, p, p_a = 0.1, 200.0, 2000.0, 1e3
    x, faces = icosahedron(r0)
    edge = np.linalg.norm(x[0] - x[11])
    c_a = edge / r0
    c_v = np.einsum("ij,ij->", x[faces[:, 0]], np.cross(x[faces[:, 1]], x[faces[:, 2]])) \
        / 6 / r0 ** 3
    gas = (p + p_a) * c_v * r0 ** 3

    def imbalance(r):
        return 30 * k * (c_a * r - edge) * c_a - (gas / (c_v * r ** 3) - p_a) * 3 * c_v * r * r
    lo, hi = r0, 2 * r0
    for _ in range(200):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if imbalance(mid) < 0 else (lo, mid)
    sim = tcloth.Simulator(balloon(x, faces, p, p_a, structural=(k, 0.5), mass=0.1,
                                   drag=0.05), "backward_euler", dt=5e-3)
    sim.step(400)
    radius = np.linalg.norm(sim.positions(), axis=1)
    assert lo > 1.05 * r0
    assert np.abs(radius / lo - 1).max() < 1e-6, (radius.min(), radius.max(), lo)


@pytest.mark.parametrize("integrator", ["symplectic_euler", "vbd", "xpbd", "projective"])
def test_every_solver_reaches_the_same_inflated_balloon(f64, integrator):
    """The balloon of the closed-form test settles to the same radius under the other
    solver families (pressure enters them at the start of each step)."""
    x, faces = icosahedron(0.1)
    scene = balloon(x, faces, 2000.0, 1e3, structural=(200.0, 0.5), mass=0.1, drag=0.05)
    reference = tcloth.Simulator(scene, "backward_euler", dt=5e-3)
    reference.step(400)
    dt, steps = (1e-4, 20000) if integrator == "symplectic_euler" else (5e-3, 400)
    sim = tcloth.Simulator(scene, integrator, dt=dt)
    sim.step(steps)
    r_ref = np.linalg.norm(reference.positions(), axis=1).mean()
    assert np.linalg.norm(sim.positions(), axis=1).mean() == pytest.approx(r_ref, rel=1e-3)


def test_winding_and_checkpoints(f64, tmp_path):
    """Faces wound inward give the same forces; a checkpoint keeps the gas (its rest
    volume too) and continues the run exactly."""
    x, faces = icosahedron(0.1)
    out = tcloth.Simulator(balloon(x, faces, 500.0, 1e4, structural=(50.0, 0.1)))
    inward = tcloth.Simulator(balloon(x, faces[:, ::-1], 500.0, 1e4, structural=(50.0, 0.1)))
    assert np.allclose(out.forces(), inward.forces(), rtol=1e-12, atol=1e-15)
    scene = balloon(x, faces, 500.0, 1e4, structural=(50.0, 0.1))
    scene.set_pressure(500.0, ambient=1e4, rest_volume=[0.003])
    sim = tcloth.Simulator(scene, "symplectic_euler", dt=1e-4)
    sim.step(10)
    sim.save(str(tmp_path / "b.npz"))
    sim.step(10)
    loaded = tcloth.Simulator.load(str(tmp_path / "b.npz"))
    assert loaded.scene.pressure["rest_volume"].tolist() == [0.003]
    loaded.step(10)
    assert np.array_equal(loaded.positions(), sim.positions())


def test_pressure_input_is_checked():
    x, faces = icosahedron(0.1)
    scene = tcloth.Scene()
    with pytest.raises(SceneError, match="cloths must be"):
        scene.set_pressure(100.0)
    scene.add_cloth(resolution=(4, 4))
    with pytest.raises(SceneError, match="cloth 0 does not enclose a volume"):
        scene.set_pressure(100.0)
    scene.add_mesh_cloth(x, faces.tolist())
    with pytest.raises(SceneError, match="above -ambient"):
        scene.set_pressure(-2e5, cloths=[1])
    with pytest.raises(SceneError, match="rest_volume must be 1"):
        scene.set_pressure(100.0, cloths=[1], rest_volume=[1.0, 2.0])
    flipped = faces.copy()
    flipped[0] = flipped[0, ::-1]
    bad = tcloth.Scene()
    bad.add_mesh_cloth(x, flipped.tolist())
    with pytest.raises(SceneError, match="consistently wound"):
        bad.set_pressure(100.0)
    assert scene.set_pressure(100.0, cloths=[1])["cloths"] == [1]
