"""Hinge bending (``tcloth.terms.bending``): the energy against closed forms (a fold, a
plate's curvature energy), its force and Hessian against finite differences, and the
solvers (backward Euler, VBD, projective, XPBD) converging to the same step."""

import numpy as np
import pytest

import tcloth
from tcloth.scene.builders import Cloth
from tcloth.scene.hinges import cloth_hinges, hinge_table
from tcloth.testing import cantilever


pytestmark = pytest.mark.usefixtures("f64")


def _grid(nx, ny, dx, dy):
    cloth = Cloth(0, (nx, ny), (dx, dy), {}, "xz")
    i, j = np.meshgrid(np.arange(nx) * dx, np.arange(ny) * dy)
    return cloth, np.stack([i, np.zeros_like(i), j], -1).reshape(-1, 3)


def _lifted(x, a, b, c):
    """x with heights z = (a x^2 + 2 b x y + c y^2) / 2 over its plane (curvatures a, c,
    twist b)."""
    out = x.copy()
    out[:, 1] = 0.5 * (a * x[:, 0] ** 2 + 2 * b * x[:, 0] * x[:, 2] + c * x[:, 2] ** 2)
    return out


def _energy(ids, weights, x):
    s = np.einsum("hk,hkd->hd", weights, x[ids])
    return 0.5 * float(np.sum(s * s))


def _rotate(p, origin, axis, angle):
    axis = axis / np.linalg.norm(axis)
    r = p - origin
    along = axis * (r @ axis)
    return origin + along + np.cos(angle) * (r - along) + np.sin(angle) * np.cross(axis, r)


@pytest.mark.parametrize("mesh", ["equilateral", "grid"])
def test_hinge_measures_its_fold(mesh):
    """s = sum K_i x_i is 0 on the flat hinge and on any rigid motion of it, and
    |s| = 2 |e| sin(theta / 2) when one wing folds by theta about the shared edge."""
    if mesh == "equilateral":
        x, tris = cantilever.equilateral_strip(1, 0.01, 2)
    else:
        cloth, x = _grid(2, 2, 0.01, 0.02)
        tris = cloth.triangles
    ids, K, _, fold = hinge_table(tris, x)
    assert len(ids) and np.all(fold < 1e-12)
    rng = np.random.default_rng(3)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    for k, h in enumerate(ids):
        moved = x[h] @ q.T + rng.normal(size=3)
        assert np.abs(K[k] @ x[h]).max() < 1e-15
        assert np.abs(K[k] @ moved).max() < 1e-13
        edge = np.linalg.norm(x[h[1]] - x[h[0]])
        for theta in (0.01, 0.5, 2.0):
            folded = x[h].copy()
            folded[3] = _rotate(folded[3], folded[0], folded[1] - folded[0], theta)
            assert np.linalg.norm(K[k] @ folded) == pytest.approx(
                2 * edge * np.sin(theta / 2), rel=1e-12)


def test_grid_energy_is_a_plate_energy():
    """On a square grid the hinges' energy of any height field of constant curvature is
    the plate energy B/2 (k_xx^2 + k_yy^2 + 2 k_xy^2) per area (Poisson's ratio 0), with
    the warp rigidity for k_xx, the weft one for k_yy, over the area the interior hinges
    cover (they stop one cell from the ends)."""
    nx, ny, h = 9, 7, 0.1
    cloth, x = _grid(nx, ny, h, h)
    warp, weft = 2.0, 0.5
    ids, weights = cloth_hinges(cloth, x, np.array([warp, weft]))
    covered_i = (nx - 2) * (ny - 1) * h * h       # hinges on sides along j: k_xx
    covered_j = (nx - 1) * (ny - 2) * h * h       # along i: k_yy
    rng = np.random.default_rng(0)
    for a, b, c in [(1, 0, 0), (0, 0, 1), (0, 1, 0)] + [tuple(rng.normal(size=3))] * 2:
        expected = 0.5 * (warp * covered_i * (a * a + b * b) + weft * covered_j * (c * c + b * b))
        assert _energy(ids, weights, _lifted(x, a, b, c)) == pytest.approx(expected, rel=1e-10)


@pytest.mark.parametrize("angle", [0, 30, 45, 60, 90, 135])
def test_bent_cloth_energy_converges_to_the_cylinder(angle):
    """A cloth bent into a cylinder of curvature kappa along any direction: B/2 kappa^2
    per area as the resolution grows, on the grid and on an equilateral mesh (the
    hinges' edge rows missing at the boundary: within 2/n of it at n cells)."""
    B, kappa = 1e-3, 2.0
    m = np.array([np.cos(np.radians(angle)), 0.0, np.sin(np.radians(angle))])
    for n in (20, 40):
        cloth, xg = _grid(n + 1, n + 1, 1.0 / n, 1.0 / n)
        xm, tm = cantilever.equilateral_strip(n - 1, 1.0 / n, n + 1)
        for x, tris, hinges in ((xg, None, cloth_hinges(cloth, xg, np.array([B, B]))),
                                (xm, tm, None)):
            if hinges is None:
                mesh = tcloth.MeshCloth(0, len(x), tris, {})
                hinges = cloth_hinges(mesh, x, np.array([B, B]))
                tris = mesh.triangles
            else:
                tris = cloth.triangles
            u = (x - x.mean(0)) @ m
            bent = x + np.outer(np.sin(kappa * u) / kappa - u, m)
            bent[:, 1] = (1 - np.cos(kappa * u)) / kappa
            area = 0.5 * np.linalg.norm(np.cross(x[tris[:, 1]] - x[tris[:, 0]],
                                                 x[tris[:, 2]] - x[tris[:, 0]]), axis=1).sum()
            ratio = _energy(*hinges, bent) / (0.5 * B * kappa ** 2 * area)
            assert 1 - 2.0 / n < ratio < 1 + 1e-3, (n, ratio)


def _bending_scene(kind="grid", gravity=0.0):
    """A small fabric cloth, or a mesh cloth with hinge bending and no springs."""
    scene = tcloth.Scene(gravity=(0.0, -gravity, 0.0))
    if kind == "grid":
        fabric = tcloth.Fabric(0.2, 20.0, 5.0, (2e-5, 1e-5), damping=0.0)
        scene.add_cloth(resolution=(6, 5), size=(0.1, 0.08), center=(0, 0, 0),
                        pinned=[(0, 0), (5, 0)], fabric=fabric)
    else:
        x, tris = cantilever.equilateral_strip(4, 0.02, 5)
        scene.add_mesh_cloth(x, [tuple(t) for t in tris.tolist()], mass=0.01,
                             structural=None, flexion=None, pinned=[0, 1])
        scene.set_bending(3e-5)
    return scene


def _perturbed(scene, scale=3e-3, seed=1):
    rng = np.random.default_rng(seed)
    return scene.positions + rng.normal(scale=scale, size=scene.positions.shape)


@pytest.mark.parametrize("kind", ["grid", "mesh"])
def test_force_is_minus_the_energy_gradient(kind):
    scene = _bending_scene(kind)
    sim = tcloth.Simulator(scene, integrator="symplectic_euler", dt=1e-4)
    x = _perturbed(scene)
    sim.set_state(positions=x)
    force = sim.forces()

    def energy(y):
        sim.set_state(positions=y)
        e = sim.energy()
        return e["bending"] + e.get("spring", 0.0)

    eps = 1e-6
    for p in (3, 7, len(x) - 1):
        for d in range(3):
            up, down = x.copy(), x.copy()
            up[p, d] += eps
            down[p, d] -= eps
            fd = -(energy(up) - energy(down)) / (2 * eps)
            assert force[p, d] == pytest.approx(fd, rel=1e-6, abs=1e-9)


def test_hessian_product_is_the_force_difference():
    """Backward Euler's Hessian of the bending (its diagonal blocks and couplings) times v
    equals -(f(x + v) - f(x)): the energy is quadratic, so exactly."""
    scene = _bending_scene("mesh")
    sim = tcloth.Simulator(scene, integrator="backward_euler", dt=1e-2)
    term = next(t for t in sim.integrator.potential.pair_terms if t.name == "bending")
    rng = np.random.default_rng(2)
    x = _perturbed(scene)
    v = rng.normal(size=x.shape)
    sim.set_state(positions=x)
    f0 = sim.forces()
    sim.set_state(positions=x + v)
    df = sim.forces() - f0
    field = tcloth.runtime.ti.Vector.field(3, tcloth.runtime.ti.f64, shape=len(x))
    field.from_numpy(v)
    out = tcloth.runtime.ti.Vector.field(3, tcloth.runtime.ti.f64, shape=len(x))
    term.add_product(field, out, True)
    product = out.to_numpy() + term.diagonal.to_numpy()[:, None] * v
    assert np.abs(product + df).max() < 1e-9 * np.abs(df).max()


@pytest.mark.slow
def test_vbd_xpbd_and_projective_converge_to_backward_euler():
    """One step from a bent state of a cloth with hinges and no springs: VBD
    (Gauss-Seidel over the hinges' colours) and XPBD (hinges as linear constraints)
    approach backward Euler's step as iterations grow, to rounding; projective reaches it
    in one iteration with an exact global solve (its constant matrix is then the exact
    Hessian)."""
    scene = _bending_scene("mesh", gravity=9.81)
    x = _perturbed(scene)
    be = tcloth.Simulator(scene, integrator="backward_euler", dt=1 / 60, newton_tol=1e-12)
    be.set_state(positions=x)
    be.step(1)
    target = be.positions()
    size = np.ptp(x, axis=0).max()

    def gap(integrator, n, **options):
        sim = tcloth.Simulator(scene, integrator=integrator, dt=1 / 60, iterations=n,
                               **options)
        sim.set_state(positions=x)
        sim.step(1)
        return np.abs(sim.positions() - target).max() / size

    for integrator, options in (("vbd", {"rho": 0.0, "substeps": 1}),
                                ("xpbd", {"substeps": 1})):
        gaps = [gap(integrator, n, **options) for n in (2, 10, 500)]
        assert gaps[0] > gaps[1] >= gaps[2] and gaps[2] < 1e-12, (integrator, gaps)
    assert gap("projective", 1, cg_tol=1e-14) < 1e-12


def test_multigrid_refuses_a_bending_scene():
    scene = _bending_scene("grid")
    with pytest.raises(tcloth.SceneError, match="one cloth grid and nothing else"):
        tcloth.Simulator(scene, integrator="backward_euler", dt=0.01,
                         linear_solver="multigrid")


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["grid", "mesh"])
def test_checkpoint_continues_a_bending_cloth(kind, tmp_path):
    """Saved mid-fall (the cloth bent), loaded, continued: the same positions bit for
    bit; the hinges keep their flat rest shape, not the bent one."""
    scene = _bending_scene(kind, gravity=9.81)
    sim = tcloth.Simulator(scene, integrator="backward_euler", dt=1 / 60)
    sim.step(10)
    sim.save(tmp_path / "bent.npz")
    sim.step(10)
    loaded = tcloth.Simulator.load(tmp_path / "bent.npz")
    loaded.step(10)
    assert np.array_equal(loaded.positions(), sim.positions())
    assert loaded.energy()["bending"] == sim.energy()["bending"] > 0


def test_set_bending_checks_its_arguments():
    scene = tcloth.Scene()
    x, tris = cantilever.equilateral_strip(2, 0.02, 3)
    scene.add_mesh_cloth(x, [tuple(t) for t in tris.tolist()])
    with pytest.raises(tcloth.SceneError, match="warp and weft"):
        scene.set_bending((1e-5, 2e-5))
    with pytest.raises(tcloth.SceneError, match="rigidity"):
        scene.set_bending(-1.0)
    with pytest.raises(tcloth.SceneError, match="cloths"):
        scene.set_bending(1e-5, cloths=[1])
    with pytest.raises(tcloth.SceneError, match="rest_positions"):
        scene.set_bending(1e-5, rest_positions=np.zeros((3, 3)))
    folded = scene.positions
    folded[-1, 1] += 0.01
    with pytest.raises(tcloth.SceneError, match="flat rest shape"):
        scene.set_bending(1e-5, rest_positions=folded)
    assert scene.bending is None
    x2 = x.copy()
    x2[-1, 1] += 0.01
    with pytest.raises(tcloth.SceneError, match="flat rest shape"):
        scene.add_mesh_cloth(x2, [tuple(t) for t in tris.tolist()], fabric=tcloth.Fabric(
            0.2, 100.0, 10.0, 1e-5))
    assert scene.num_particles == len(x)
