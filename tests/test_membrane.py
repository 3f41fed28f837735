"""The triangle membrane (``tcloth.terms.membrane``): its energy against closed forms for
homogeneous deformations on any triangulation, its forces against finite differences,
equilibrium and traction, momentum, its Hessian, and the solvers (VBD, XPBD, projective)
converging to backward Euler's step with it."""

import numpy as np
import pytest

import tcloth
from tcloth.testing import cantilever

CU, CV, G = 300.0, 120.0, 7.0                 # N/m: warp, weft, shear


pytestmark = pytest.mark.usefixtures("f64")


def _mesh(irregular=False, cells=6, rows=6, spacing=0.02):
    """(vertices, triangles) of an equilateral strip in the xz plane; ``irregular`` moves
    its interior vertices in the plane by up to a fifth of a spacing."""
    x, tris = cantilever.equilateral_strip(cells, spacing, rows)
    if irregular:
        rng = np.random.default_rng(3)
        lo, hi = x.min(axis=0), x.max(axis=0)
        inside = np.all((x[:, [0, 2]] > lo[[0, 2]] + 1e-9) & (x[:, [0, 2]] < hi[[0, 2]] - 1e-9),
                        axis=1)
        x[inside, 0] += rng.uniform(-0.2, 0.2, inside.sum()) * spacing
        x[inside, 2] += rng.uniform(-0.2, 0.2, inside.sum()) * spacing
    return x, tris


def _scene(irregular=False, damping=0.0, gravity=0.0, pinned=(), mass=0.01):
    x, tris = _mesh(irregular)
    scene = tcloth.Scene(gravity=(0.0, -gravity, 0.0))
    scene.add_mesh_cloth(x, [tuple(t) for t in tris.tolist()], mass=mass, structural=None,
                         flexion=None, pinned=pinned)
    scene.set_membrane((CU, CV), G, damping=damping)
    area = 0.5 * np.linalg.norm(np.cross(x[tris[:, 1]] - x[tris[:, 0]],
                                         x[tris[:, 2]] - x[tris[:, 0]]), axis=1).sum()
    return scene, area


def _energy(sim, x):
    sim.set_state(positions=x)
    return sim.energy()["membrane"]


@pytest.mark.parametrize("irregular", [False, True])
def test_homogeneous_deformations_have_the_closed_form_energy(irregular):
    """x = F X on every vertex: the energy is the area times the energy density of F,
    on an equilateral mesh and on an irregular one alike (stretch along warp and weft
    uncoupled, shear with its own stiffness, nothing for a rotation)."""
    scene, area = _scene(irregular)
    sim = tcloth.Simulator(scene, integrator="symplectic_euler", dt=1e-4)
    X = scene.positions
    lam, gamma = 1.07, 0.2
    warp = np.diag([lam, 1.0, 1.0])
    weft = np.diag([1.0, 1.0, lam])
    shear = np.array([[1.0, 0.0, gamma], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    c, s = np.cos(0.7), np.sin(0.7)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    expected = {
        "warp": 0.5 * CU * (lam - 1) ** 2,
        "weft": 0.5 * CV * (lam - 1) ** 2,
        "shear": 0.5 * CV * (np.hypot(1.0, gamma) - 1) ** 2 + 0.5 * G * gamma ** 2,
    }
    for name, F in (("warp", warp), ("weft", weft), ("shear", shear)):
        assert _energy(sim, X @ F.T) == pytest.approx(area * expected[name], rel=1e-10), name
        assert _energy(sim, X @ (rotation @ F).T) == pytest.approx(area * expected[name],
                                                                   rel=1e-10), name
    assert abs(_energy(sim, X @ rotation.T + 0.3)) < 1e-20


def test_a_stretched_strip_is_in_equilibrium_inside_and_pulls_with_the_stiffness():
    """Stretched homogeneously along the warp, the interior vertices feel no force (to
    rounding) and the strip's right half is pulled back by C_u (lambda - 1) per width."""
    scene, _ = _scene(irregular=True)
    sim = tcloth.Simulator(scene, integrator="symplectic_euler", dt=1e-4)
    X = scene.positions
    lam = 1.01
    sim.set_state(positions=X * np.array([lam, 1.0, 1.0]))
    f = sim.forces()
    lo, hi = X.min(axis=0), X.max(axis=0)
    cell = 0.02
    inside = np.all((X[:, [0, 2]] > lo[[0, 2]] + cell) & (X[:, [0, 2]] < hi[[0, 2]] - cell),
                    axis=1)
    scale = CU * (lam - 1) * cell
    assert np.abs(f[inside]).max() < 1e-12 * scale
    width = hi[2] - lo[2]
    right = X[:, 0] > 0.5 * (lo[0] + hi[0])
    assert -f[right, 0].sum() == pytest.approx(CU * (lam - 1) * width, rel=1e-10)
    assert np.abs(f[:, [1, 2]].sum(axis=0)).max() < 1e-12 * scale


def test_force_is_minus_the_energy_gradient():
    scene, _ = _scene(irregular=True)
    sim = tcloth.Simulator(scene, integrator="symplectic_euler", dt=1e-4)
    rng = np.random.default_rng(1)
    x = scene.positions + rng.normal(scale=2e-3, size=scene.positions.shape)
    sim.set_state(positions=x)
    force = sim.forces()
    eps = 1e-6
    for p in (0, 9, 20, len(x) - 1):
        for d in range(3):
            up, down = x.copy(), x.copy()
            up[p, d] += eps
            down[p, d] -= eps
            fd = -(_energy(sim, up) - _energy(sim, down)) / (2 * eps)
            assert force[p, d] == pytest.approx(fd, rel=1e-6, abs=1e-9)


def test_damping_keeps_momentum_and_dissipates():
    """With random positions and velocities the damped membrane's forces sum to zero and
    have no torque; the damping's power f_d . v is negative, and a rigid motion is not
    damped."""
    scene, _ = _scene(irregular=True, damping=0.5)
    sim = tcloth.Simulator(scene, integrator="symplectic_euler", dt=1e-4)
    rng = np.random.default_rng(4)
    x = scene.positions + rng.normal(scale=2e-3, size=scene.positions.shape)
    v = rng.normal(size=x.shape)
    sim.set_state(positions=x, velocities=np.zeros_like(x))
    elastic = sim.forces()
    sim.set_state(positions=x, velocities=v)
    f = sim.forces()
    scale = np.abs(f).max()
    assert np.abs(f.sum(axis=0)).max() < 1e-12 * scale
    assert np.abs(np.cross(x, f).sum(axis=0)).max() < 1e-12 * scale
    assert np.sum((f - elastic) * v) < 0
    omega = np.array([0.3, -1.0, 2.0])
    sim.set_state(positions=x, velocities=np.cross(omega, x) + 0.5)
    assert np.abs(sim.forces() - elastic).max() < 1e-12 * np.abs(elastic).max()


def _product(term, x, x0, v, h):
    ti = tcloth.runtime.ti
    fields = []
    for a in (x, x0, v):
        f = ti.Vector.field(3, ti.f64, shape=len(a))
        f.from_numpy(a)
        fields.append(f)
    out = ti.Vector.field(3, ti.f64, shape=len(x))
    term.prepare_blocks(fields[0], fields[1], h)
    term.add_product(fields[2], out, True)
    return out.to_numpy() + np.einsum("pij,pj->pi", term.block.to_numpy(), v)


def _forces_derivative(sim, x, v, eps=1e-6):
    sim.set_state(positions=x + eps * v)
    up = sim.forces()
    sim.set_state(positions=x - eps * v)
    return -(up - sim.forces()) / (2 * eps)


@pytest.mark.slow
def test_hessian_products_are_the_force_derivative_and_the_projection_is_never_negative():
    """Backward Euler's Hessian of the membrane (diagonal blocks and couplings) times v:
    exact, -(df/dx) v in any state (here compressed, sheared and bent); projected
    (``exact_hessian=False``), the same where the projection drops nothing (stretched
    along the warp: no shear, no compression), and v . H v >= 0 in any state."""
    scene, _ = _scene(irregular=True)
    X = scene.positions
    rng = np.random.default_rng(5)
    v = rng.normal(size=X.shape)
    exact = tcloth.Simulator(scene, integrator="backward_euler", dt=1e-2)
    projected = tcloth.Simulator(scene, integrator="backward_euler", dt=1e-2,
                                 exact_hessian=False)
    terms = [next(t for t in sim.integrator.potential.pair_terms if t.name == "membrane")
             for sim in (exact, projected)]
    general = X @ np.array([[0.9, 0.0, 0.3], [0.0, 1.0, 0.0], [0.1, 0.0, 0.95]]).T \
        + rng.normal(scale=2e-3, size=X.shape)
    fd = _forces_derivative(exact, general, v)
    assert np.abs(_product(terms[0], general, general, v, 1e-2) - fd).max() \
        < 1e-6 * np.abs(fd).max()
    stretched = X * np.array([1.05, 1.0, 1.02])
    fd = _forces_derivative(exact, stretched, v)
    assert np.abs(_product(terms[1], stretched, stretched, v, 1e-2) - fd).max() \
        < 1e-6 * np.abs(fd).max()
    for seed in range(5):
        y = X + np.random.default_rng(seed).normal(scale=5e-3, size=X.shape)
        w = np.random.default_rng(10 + seed).normal(size=X.shape)
        assert np.sum(w * _product(terms[1], y, X, w, 1e-2)) >= 0.0


@pytest.mark.slow
def test_vbd_xpbd_and_projective_converge_to_backward_euler():
    """One step of 1/60 from a perturbed, moving state of a hanging membrane (heavy enough
    that the iterations converge in a few hundred sweeps): VBD reaches backward Euler's
    step, damping included (its damping potential is VBD's); undamped, projective with its
    constant bound reaches it too (damped, its fixed point is the step with the damping at
    the step's end, not at its start), and XPBD falls towards it to its own fixed point,
    linearly: each ten more iterations shrink the change in its step about 40-fold (at
    least 10-fold asked), and the fixed point is within 2 % of the move of backward
    Euler's step (0.74 %; 4.3 % after two iterations)."""
    def target(scene, x, v):
        be = tcloth.Simulator(scene, integrator="backward_euler", dt=1 / 60,
                              newton_tol=1e-13, cg_tol=1e-13, newton_iterations=60)
        be.set_state(positions=x, velocities=v)
        be.step(1)
        return be.positions()

    def steps(scene, x, v, integrator, counts, **options):
        # one simulator, its steps from Python, which read the iteration count each step
        sim = tcloth.Simulator(scene, integrator=integrator, dt=1 / 60, batch=False,
                               **options)
        out = []
        for n in counts:
            sim.set_integrator_options(iterations=n)
            sim.set_state(positions=x, velocities=v)
            sim.step(1)
            out.append(sim.positions())
        return out

    def gaps(scene, x, v, goal, integrator, counts, **options):
        return [np.abs(y - goal).max()
                for y in steps(scene, x, v, integrator, counts, **options)]

    rng = np.random.default_rng(6)
    damped, _ = _scene(damping=0.2, gravity=9.81, pinned=[0, 7], mass=1.0)
    x = damped.positions + rng.normal(scale=1e-3, size=damped.positions.shape)
    v = rng.normal(scale=0.05, size=x.shape)
    goal = target(damped, x, v)
    moved = np.abs(goal - x).max()
    g = gaps(damped, x, v, goal, "vbd", (2, 10, 100), rho=0.0, substeps=1)
    assert g[0] > g[1] > g[2] and g[2] < 1e-12 * moved, g
    undamped, _ = _scene(gravity=9.81, pinned=[0, 7], mass=1.0)
    goal = target(undamped, x, v)
    g = gaps(undamped, x, v, goal, "projective", (2, 20, 400), cg_tol=1e-13,
             cg_max_iterations=1000)
    assert g[0] > g[1] > g[2] and g[2] < 1e-10 * moved, g
    y = steps(undamped, x, v, "xpbd", (2, 10, 20, 30, 40, 400), substeps=1)
    change = [np.abs(b - a).max() for a, b in zip(y[1:4], y[2:5])]     # 10 -> 20 -> 30 -> 40
    assert change[0] > 10 * change[1] > 100 * change[2] > 0, change
    g = [np.abs(y[0] - goal).max(), np.abs(y[-1] - goal).max()]
    assert g[0] > 0.02 * moved > g[1], (g, moved)


@pytest.mark.slow
def test_a_mesh_fabric_has_its_shear_and_the_checkpoint_keeps_it(tmp_path):
    """``add_mesh_cloth(fabric=...)`` gives the mesh a membrane with the fabric's stretch
    and shear and no springs; a checkpoint continues it bit for bit."""
    x, tris = _mesh()
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0))
    fabric = tcloth.Fabric(0.2, (CU, CV), G, 1e-6, damping=0.3)
    scene.add_mesh_cloth(x, [tuple(t) for t in tris.tolist()], pinned=[0, 7], fabric=fabric)
    assert sum(scene.spring_counts().values()) == 0
    assert scene.membrane["stretch"].tolist() == [[CU, CV]]
    assert scene.membrane["shear"].tolist() == [G]
    sim = tcloth.Simulator(scene, integrator="vbd", dt=1 / 60)
    sim.step(5)
    sim.save(tmp_path / "m.npz")
    sim.step(5)
    loaded = tcloth.Simulator.load(tmp_path / "m.npz")
    loaded.step(5)
    assert np.array_equal(loaded.positions(), sim.positions())
    assert loaded.energy()["membrane"] == sim.energy()["membrane"] > 0


@pytest.mark.slow_cases("vbd", "xpbd")
@pytest.mark.parametrize("integrator", ["symplectic_euler", "vbd", "xpbd"])
def test_a_batch_of_steps_equals_single_steps_bit_for_bit(integrator):
    """The membrane is in-kernel: n steps in one launch (``batch.py``) are the single
    steps' numbers exactly, damping and gravity included."""
    def run(batch, chunks):
        scene, _ = _scene(damping=0.3, gravity=9.81, pinned=[0, 7])
        sim = tcloth.Simulator(scene, integrator=integrator, batch=batch,
                               dt=1e-4 if integrator == "symplectic_euler" else 1 / 60)
        assert (sim.fusion() is None) == batch
        for n in chunks:
            sim.step(n)
        return sim

    single, batched = run(False, [1] * 6), run(True, [4, 2])
    assert np.array_equal(batched.positions(), single.positions())
    assert np.array_equal(batched.velocities(), single.velocities())
    assert single.energy()["membrane"] > 0.0


def test_set_membrane_checks_its_arguments():
    scene = tcloth.Scene()
    x, tris = _mesh()
    scene.add_mesh_cloth(x, [tuple(t) for t in tris.tolist()])
    for kwargs, match in (({"stretch": -1.0, "shear": 1.0}, "stretch"),
                          ({"stretch": 1.0, "shear": 0.0}, "shear"),
                          ({"stretch": 1.0, "shear": [1.0, 2.0]}, "shear"),
                          ({"stretch": 1.0, "shear": 1.0, "damping": -0.1}, "damping"),
                          ({"stretch": 1.0, "shear": 1.0, "cloths": [1]}, "cloths"),
                          ({"stretch": 1.0, "shear": 1.0, "rest_positions": np.zeros((3, 3))},
                           "rest_positions")):
        with pytest.raises(tcloth.SceneError, match=match):
            scene.set_membrane(**kwargs)
    flat = scene.positions
    flat[tris[0, 2]] = flat[tris[0, 0]]
    with pytest.raises(tcloth.SceneError, match="degenerate"):
        scene.set_membrane(1.0, 1.0, rest_positions=flat)
    assert scene.membrane is None
