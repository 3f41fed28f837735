"""Implicit integrators: backward Euler (stiff stability, energy decrease, Hessian
consistency, order 1) and Liu et al.'s projective solver (agreement with backward Euler);
both reach the static equilibrium of a long explicit run."""
import numpy as np
import pytest
import taichi as ti

import tcloth
from tcloth import InstabilityError
from conftest import numpy_forces, random_network


def cloth(k, kd=1.0, n=8, pinned=None):
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(n, n), size=(1, 1), structural=(k, kd), shear=(k / 10, kd / 2),
                    flexion=(k / 100, kd / 10), pinned=pinned)
    return scene


@pytest.mark.slow
@pytest.mark.parametrize("k", [1e4, 1e6])
def test_stiff_cloth_explodes_explicitly_but_is_stable_and_dissipative_implicitly(f64, k):
    with pytest.raises(InstabilityError):
        tcloth.Simulator(cloth(k), "symplectic_euler", dt=1 / 60, split=False).step(200)
    sim = tcloth.Simulator(cloth(k, n=6), "backward_euler", dt=1 / 60)
    energy = [sim.energy()["total"]]
    for _ in range(20):
        sim.step()
        energy.append(sim.energy()["total"])
    assert np.all(np.diff(energy) <= 1e-9 * abs(energy[0]))
    assert energy[-1] < energy[0]
    assert sim.max_strain() < 0.05
    # projective with 10 iterations: unconverged for such stiffness (residual strain holds
    # spring energy), but stable: no blow-up, small strain, energy decaying; on 6 x 6 with
    # exact global solves, at the highest stiffness also on 16 x 16 with multigrid
    for n in (6, 16) if k > 1e5 else (6,):
        pd = tcloth.Simulator(cloth(k, n=n), "projective", dt=1 / 60)
        pd.step(15)
        e15 = pd.energy()["total"]
        pd.step(15)
        assert pd.max_strain() < 0.05 and pd.energy()["total"] < e15


def stiff_pinned_cloth(n, k):
    """A stiff cloth that strains Newton's line search (docs/implicit.md): 0.2 kg, pinned
    at two corners, no damping, k_s = k structural, k / 10 shear, k / 100 flexion."""
    scene = tcloth.Scene(gravity=(0, -9.81, 0))
    scene.add_cloth(resolution=(n, n), size=(1, 1), center=(0, 1, 0), plane="xz", mass=0.2,
                    structural=(k, 0.0), shear=(k / 10, 0.0), flexion=(k / 100, 0.0),
                    pinned=[(0, 0), (n - 1, 0)])
    return scene


def potential_never_rises(stats, slack):
    e = np.array(stats["potential"])
    return bool(np.all(np.diff(e) <= slack * max(1.0, np.abs(e).max())))


@pytest.mark.slow
@pytest.mark.parametrize("precision", ["f32", "f64"])
def test_newton_never_raises_the_incremental_potential_and_reports_non_convergence(precision):
    """The undamped, pinned 32 x 32 cloth of k_s = 1e5 at dt = 1/60, where truncated CG
    returns huge directions along which 14 halvings may find no decrease of E
    (docs/implicit.md): no accepted iterate raises E beyond rounding, no converged step
    gains energy, and across stiffnesses 1e2 to 1e6 (16 x 16, changed live) a step that
    stops at its iteration cap says so: stats, the ``unconverged`` count, one
    ConvergenceWarning."""
    tcloth.init(arch="cpu", precision=precision)
    slack = 1e-5 if precision == "f32" else 1e-12
    sim = tcloth.Simulator(stiff_pinned_cloth(32, 1e5), "backward_euler", dt=1 / 60)
    energy = [sim.energy()["total"]]
    scale = 0.2 * 9.81 * 1.0
    for _ in range(12):
        sim.step()
        energy.append(sim.energy()["total"])
        stats = sim.integrator.stats
        assert potential_never_rises(stats, slack), stats["potential"]
        if stats["converged"]:
            assert energy[-1] <= energy[-2] + 1e-4 * scale, (sim.num_steps, energy[-2:])
    assert max(energy) <= energy[0] + 1e-4 * scale
    sim = tcloth.Simulator(stiff_pinned_cloth(16, 1e2), "backward_euler", dt=1 / 60,
                           newton_iterations=3)
    unconverged = 0
    with pytest.warns(tcloth.ConvergenceWarning, match="newton_iterations") as caught:
        for k in (1e2, 1e3, 1e4, 1e5, 1e6):
            sim.reset()
            for kind in ("structural", "shear", "flexion"):
                sim.set_springs(kind, stiffness=k / {"structural": 1, "shear": 10,
                                                     "flexion": 100}[kind])
            for _ in range(4):
                sim.step()
                stats = sim.integrator.stats
                assert potential_never_rises(stats, slack), (k, stats["potential"])
                unconverged += not stats["converged"]
    assert unconverged > 0 and sim.integrator.unconverged == unconverged
    assert len([w for w in caught if w.category is tcloth.ConvergenceWarning]) == 1


@pytest.mark.slow
def test_a_newton_direction_too_long_to_search_is_replaced_not_taken(f64, monkeypatch):
    """CG stopped at negative curvature can return a descent direction of any length
    (docs/implicit.md). Scaled by 1e7, no step the line search tries lowers E: Newton then
    takes the preconditioned gradient, not the smallest step (which would raise E), and E
    still falls."""
    sim = tcloth.Simulator(stiff_pinned_cloth(8, 1e3), "backward_euler", dt=1 / 60)
    sim.step(3)
    be = sim.integrator
    solve = be.hessian.solve

    def too_long(grad, tol, iterations):
        result = solve(grad, tol, iterations)
        tcloth.integrators.linalg.scale_into(be.hessian.dx, 1e7, be.hessian.dx)
        return result
    monkeypatch.setattr(be.hessian, "solve", too_long)
    before = sim.energy()["total"]
    for _ in range(3):
        sim.step()
        stats = be.stats
        assert stats["fallbacks"] >= 1 and potential_never_rises(stats, 1e-12)
        assert stats["potential"][-1] < stats["potential"][0]
    assert sim.energy()["total"] <= before + 1e-9


@pytest.mark.slow
def test_hessian_product_matches_finite_differences_of_the_gradient(f64):
    scene = tcloth.Scene(gravity=(0, -9.81, 0), air_drag=0.05)
    c = scene.add_cloth(resolution=(4, 3), size=(0.6, 0.4), center=(0, 0.003, 0),
                        structural=(300.0, 0.4), shear=(50.0, 0.1), flexion=(5.0, 0.02),
                        pinned=[(0, 0)])
    scene.add_plane((0, 0, 0), (0, 1, 0), friction=0.4, thickness=0.01, stiffness=800.0)
    for solver in ("multigrid", "cg"):     # the grid's block stencil; blocks per spring end
        hessian_product_matches_finite_differences(scene, c.particles[0, 0], solver)


def hessian_product_matches_finite_differences(scene, pinned, solver):
    sim = tcloth.Simulator(scene, "backward_euler", dt=0.01, linear_solver=solver)
    rng = np.random.default_rng(0)
    # stretch every spring (the definiteness fix is then inactive) and move the cloth
    x = scene.positions * [1.15, 1.0, 1.15] + 0.002 * rng.normal(size=(12, 3))
    v = 0.3 * rng.normal(size=(12, 3))
    sim.set_state(positions=x, velocities=v)
    be, h = sim.integrator, sim.dt
    probe = sim.model.state()
    be.potential.begin(sim.state.x, sim.state.v, h, 0.0, probe.x)
    y = x + 0.004 * rng.normal(size=x.shape)            # an iterate near x0 + h v0
    direction = rng.normal(size=x.shape)
    direction[pinned] = 0.0
    probe.v.from_numpy(direction)
    probe.x.from_numpy(y)
    hp = be.hessian_product(probe.x, probe.v, h)

    def gradient(at):
        probe.x.from_numpy(at)
        be.potential.evaluate(probe.x, h, 0.0, True)
        return be.potential.grad.to_numpy()
    eps = 1e-6
    fd = (gradient(y + eps * direction) - gradient(y - eps * direction)) / (2 * eps)
    free = np.ones(12, dtype=bool)
    free[pinned] = False
    assert np.allclose(hp[free], fd[free], rtol=1e-5, atol=1e-5 * np.abs(fd).max())

    def energy(at):
        probe.x.from_numpy(at)
        return be.potential.evaluate(probe.x, h, 0.0, False)[0]
    g = gradient(y)
    fd_e = (energy(y + eps * direction) - energy(y - eps * direction)) / (2 * eps)
    assert np.isclose(fd_e, (g * direction).sum(), rtol=1e-6)


@pytest.mark.slow
def test_newton_on_the_exact_hessian_converges_quadratically_on_folded_cloth(f64):
    """The benchmark's cloth (16 x 16, 0.1 kg, k_s = 1e4, no damping) folded by a second
    of swinging (projective steps, quick): its compressed springs make the step's Hessian
    indefinite. CG on the exact Hessian (stopped at negative curvature, preconditioned by
    the projected one) takes Newton to the backward Euler step in a few iterations: the
    NumPy residual M (x0 + h v0 - x) / h^2 + f(x) of the free particles drops below 1e-9
    of its start. CG on the projected Hessian (the definiteness fix alone) converges
    linearly: more than three times the iterations for the same step-size tolerance, and
    a residual 10 times larger or more, since a linear rate leaves more behind its last
    step than a quadratic one (docs/implicit.md has the counts and residuals)."""
    n, h = 16, 1 / 60
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(n, n), size=(0.1 * (n - 1),) * 2, mass=0.1 * n * n,
                    structural=(1e4, 0.0), shear=(1e4, 0.0), flexion=(1e4, 0.0))
    warm = tcloth.Simulator(scene, "projective", dt=h)
    warm.step(60)
    x0, v0 = warm.positions(), warm.velocities()
    free = ~scene.pinned

    def residual(x):
        f = numpy_forces(scene, x, 0 * x)
        return np.abs((scene.masses[:, None] * (x0 + h * v0 - x) / h ** 2 + f)[free]).max()
    start = residual(x0 + h * v0)
    runs = {}
    for exact in (True, False):
        sim = tcloth.Simulator(scene, "backward_euler", dt=h, exact_hessian=exact,
                               newton_iterations=30, newton_tol=1e-11, cg_tol=1e-10,
                               linear_solver="cg")
        sim.set_state(positions=x0, velocities=v0)
        sim.step()
        runs[exact] = (sim.integrator.stats["newton_iterations"], residual(sim.positions()))
    assert runs[True][0] <= 6 and runs[True][1] < 1e-9 * start, runs
    assert runs[False][0] > 3 * runs[True][0] and runs[False][1] > 10 * runs[True][1], runs


@pytest.mark.slow
def test_multigrid_and_block_jacobi_cg_give_the_same_backward_euler_steps(f64):
    """The grid's block stencil with multigrid-preconditioned CG (the default on a cloth
    grid; 10 x 10: two levels) against blocks per spring end with block-Jacobi CG, both
    converged far below the tolerance compared: a cloth, two corners pinned, landing on a
    sphere with friction (contact blocks). Later steps are left out: with contacts
    switching on and off, Newton takes its 30 iterations at some steps, and the two runs
    then differ by the unconverged part (1e-7)."""
    scene = tcloth.Scene(air_drag=0.02)
    scene.add_cloth(resolution=(10, 10), size=(1, 1), center=(0, 0.3, 0),
                    structural=(2e3, 0.5), shear=(400.0, 0.1), flexion=(40.0, 0.01))
    scene.add_sphere((0.1, 0, 0), 0.3, friction=0.3, thickness=0.01)
    out = []
    for solver in ("multigrid", "cg"):
        sim = tcloth.Simulator(scene, "backward_euler", dt=1 / 60, linear_solver=solver,
                               newton_tol=1e-10, cg_tol=1e-11, newton_iterations=30)
        assert (sim.integrator.grid is not None) == (solver == "multigrid")
        sim.step(2)
        assert sim.integrator.stats["newton_iterations"] < 30
        out.append(sim.positions())
    assert np.linalg.norm(out[0] - [0.1, 0, 0], axis=1).min() < 0.31      # in contact
    assert np.abs(out[0] - out[1]).max() < 1e-12


@pytest.mark.slow
def test_backward_euler_converges_with_order_one(f64):
    scene = random_network(n=5, seed=11, k=(20.0, 60.0))
    t_end = 0.4
    ref = tcloth.Simulator(scene, "rk4", dt=t_end / 1600)
    ref.step(1600)
    errors = []
    for steps in (50, 100, 200):
        sim = tcloth.Simulator(scene, "backward_euler", dt=t_end / steps, newton_tol=1e-9,
                               cg_tol=1e-10, newton_iterations=20)
        sim.step(steps)
        errors.append(np.abs(sim.positions() - ref.positions()).max())
    order = np.log2(np.array(errors[:-1]) / errors[1:])
    assert np.allclose(order, 1.0, atol=0.15), order


def swinging(n, kd):
    """A hanging cloth 20 backward Euler steps after release from flat: (scene factory,
    positions, velocities)."""
    def scene():
        return cloth(1e3, kd=kd, n=n)
    warm = tcloth.Simulator(scene(), "backward_euler", dt=1 / 60)
    warm.step(20)
    return scene, warm.positions(), warm.velocities()


def one_step(scene, x0, v0, integrator, **options):
    sim = tcloth.Simulator(scene(), integrator, dt=1 / 60, **options)
    sim.set_state(positions=x0, velocities=v0)
    sim.step()
    return sim


@pytest.mark.slow
def test_projective_converges_to_the_backward_euler_step(f64):
    """On a 16 x 16 cloth (three multigrid levels); the 5 x 5 damped case below has exact
    global solves."""
    scene, x0, v0 = swinging(16, kd=0.0)
    be = one_step(scene, x0, v0, "backward_euler", newton_tol=1e-12, cg_tol=1e-13,
                  newton_iterations=60)
    moved = np.abs(be.positions() - x0).max()
    pd = tcloth.Simulator(scene(), "projective", dt=1 / 60)
    runs = {}
    for iterations in (10, 100, 1000):          # one simulator (one compile), re-run
        pd.set_integrator_options(iterations=iterations)
        pd.set_state(positions=x0, velocities=v0)
        pd.step()
        runs[iterations] = (pd.positions(), pd.integrator.stats["residual"])
    gaps = [np.abs(x - be.positions()).max() for x, _ in runs.values()]
    # local/global converges linearly
    assert gaps[0] > 3 * gaps[1] > 9 * gaps[2]
    assert gaps[2] < 1e-2 * moved
    assert runs[1000][1] < 1e-2
    # one V-cycle per global solve lands where exact solves do, within 10 % of the ten
    # iterations' distance from the converged step
    exact = one_step(scene, x0, v0, "projective", linear_solver="cg", cg_tol=1e-10,
                     cg_max_iterations=2000)
    assert np.abs(runs[10][0] - exact.positions()).max() < 0.1 * gaps[0]


@pytest.mark.slow
def test_anderson_acceleration_reaches_the_same_step_in_fewer_iterations(f64):
    """Anderson acceleration (``integrators/anderson.py``) converges to the fixed point of
    Liu's iterations, the backward Euler step, further in the same iterations: on the
    swinging 16 x 16 cloth, with the V-cycle's global step and with CG's (measured: 30
    accelerated iterations 0.12 and 0.09 of the plain ones' distance from the step, as
    far as 300 plain ones; 300 accelerated 3.3e-5 and 8.5e-6 of 300 plain ones')."""
    scene, x0, v0 = swinging(16, kd=0.0)
    be = one_step(scene, x0, v0, "backward_euler", newton_tol=1e-12, cg_tol=1e-13,
                  newton_iterations=60)
    for solver in ("multigrid", "cg"):
        gaps = {}
        for depth in (0, 5):
            pd = tcloth.Simulator(scene(), "projective", dt=1 / 60, anderson=depth,
                                  linear_solver=solver, cg_tol=1e-8)
            for iterations in (30, 300):
                pd.set_integrator_options(iterations=iterations)
                pd.set_state(positions=x0, velocities=v0)
                pd.step()
                gaps[depth, iterations] = np.abs(pd.positions() - be.positions()).max()
        assert gaps[5, 30] < 0.25 * gaps[0, 30]
        assert gaps[5, 300] < 1e-3 * gaps[0, 300]


def test_anderson_is_checked():
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(4, 4), size=(1, 1))
    for depth in (-1, 2.5, True):
        with pytest.raises(tcloth.SceneError, match=f"anderson.*{depth!r}"):
            tcloth.Simulator(scene, "projective", anderson=depth)


@pytest.mark.slow
def test_projective_converges_to_backward_euler_with_axial_spring_damping(f64):
    """The fixed point solves M (x - x0 - h v0) / h^2 = f(x, (x - x0) / h) with the
    lecture's axial damping (NumPy forces), not a damping of the whole relative velocity."""
    scene, x0, v0 = swinging(5, kd=5.0)
    h = 1 / 60
    free = ~scene().pinned

    def residual(x, damped=True):
        v = (x - x0) / h if damped else 0 * v0
        f = numpy_forces(scene(), x, v)
        return (scene().masses[:, None] * (x0 + h * v0 - x) / h ** 2 + f)[free]
    pd = one_step(scene, x0, v0, "projective", iterations=1000)
    start = np.abs(residual(x0 + h * v0)).max()
    assert np.abs(residual(pd.positions())).max() < 1e-5 * start
    # the damping forces are a real part of that balance
    assert np.abs(residual(pd.positions(), damped=False)).max() > 1e-2 * start


@pytest.mark.slow
def test_projective_grid_kernel_matches_the_general_path(f64):
    """On a grid of at most 64 particles the multigrid cycle is an exact solve, so the
    fused grid iteration (stencil springs, gravity, drag) and the general one
    (compute_forces, CG to 1e-12) must take the same steps, wind and attraction (in y)
    included."""
    def scene():
        s = tcloth.Scene(air_drag=0.02)
        s.add_cloth(resolution=(8, 7), size=(0.7, 0.6), structural=(800.0, 0.5),
                    shear=(100.0, 0.2), flexion=(20.0, 0.05))
        s.set_wind(velocity=(1.0, 0.5, 3.0), drag=0.8, lift=0.3, tangential=0.05)
        s.add_attraction(G=1e-3, softening=0.05)
        return s
    runs = []
    for solver in ("multigrid", "cg"):
        sim = tcloth.Simulator(scene(), "projective", dt=1 / 60, linear_solver=solver,
                               cg_tol=1e-12, cg_max_iterations=1000)
        sim.step(8)
        runs.append(sim.positions())
    moved = np.abs(runs[1] - scene().positions).max()
    assert moved > 0.05
    assert np.abs(runs[0] - runs[1]).max() < 1e-9 * moved


@pytest.mark.slow_cases("projective")
@pytest.mark.parametrize("integrator", ["projective", "backward_euler"])
def test_linear_solver_is_checked(integrator):
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(4, 4), size=(1, 1))
    with pytest.raises(tcloth.SceneError, match="linear_solver.*'lu'"):
        tcloth.Simulator(scene, integrator, linear_solver="lu")
    scene.add_particles([[0.0, 2.0, 0.0]])
    with pytest.raises(tcloth.SceneError, match="multigrid.*one cloth grid"):
        tcloth.Simulator(scene, integrator, linear_solver="multigrid")
    sim = tcloth.Simulator(scene, integrator, linear_solver="auto")
    assert sim.integrator.grid is None
    sim.step()


def test_line_search_takes_full_steps_whose_energy_change_is_rounding(f64):
    """In float32, at a converged backward Euler step of a folded cloth, steps of 1e-8 m
    change E by far less than its rounding error: the Armijo test would compare rounding
    and backtrack at random, so the line search takes them whole. Random steps of 1 cm,
    which stretch springs and raise E by far more than its rounding, are still cut."""
    try:
        tcloth.init(arch="cpu")
        # block Jacobi: the same line search as the multigrid's, quicker to compile
        sim = tcloth.Simulator(cloth(1e4, n=12), "backward_euler", dt=1 / 60,
                               linear_solver="cg")
        sim.step(30)
        be, h = sim.integrator, sim.dt
        t = sim.time
        x = sim.state.x          # the last step's end: x0, x_hat and d0 are still its own
        energy = be.potential.evaluate(x, h, t, True)[0]
        dx = be.hessian.dx
        rng = np.random.default_rng(0)
        for _ in range(5):
            dx.from_numpy(1e-8 * rng.normal(size=x.shape + (3,)).astype(np.float32))
            assert be.line_search(x, h, t, energy)[0] == 1.0
        dx.from_numpy(1e-2 * rng.normal(size=x.shape + (3,)).astype(np.float32))
        assert be.line_search(x, h, t, energy)[0] < 0.1
    finally:
        tcloth.init(arch="cpu", precision="f64")


def test_exact_hessian_is_checked_and_needs_the_line_search():
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(4, 4), size=(1, 1))
    with pytest.raises(tcloth.SceneError, match="exact_hessian=True needs line_search"):
        tcloth.Simulator(scene, "backward_euler", exact_hessian=True, line_search=False)
    with pytest.raises(tcloth.SceneError, match="exact_hessian must be.*'yes'"):
        tcloth.Simulator(scene, "backward_euler", exact_hessian="yes")
    # the exact Hessian goes with the line search; "auto" takes the multigrid either way
    for line_search in (True, False):
        sim = tcloth.Simulator(scene, "backward_euler", line_search=line_search)
        assert sim.integrator.exact is line_search
        assert sim.integrator.grid is not None


@pytest.mark.slow
def test_projective_keeps_particles_out_of_colliders(f64):
    """A light stiff cloth dropped onto a sphere resting on the ground: the colliders'
    penalty is inside the iterations, so the cloth never comes within half the thickness
    of either collider's surface (the penalty holds it in the offset's outer half), the
    multigrid-preconditioned and the Jacobi-preconditioned global solves give the same
    motion (to within a millimetre after 60 steps: each solve stops at cg_tol), and it
    comes to rest."""
    runs = []
    for solver in ("auto", "cg"):
        scene = tcloth.Scene()
        scene.add_cloth(resolution=(8, 8), size=(1, 1), center=(0, 0.3, 0), pinned=[],
                        structural=(1e4, 0.5), shear=(1e3, 0.1), flexion=(100.0, 0.01))
        scene.add_sphere((0, 0, 0), 0.2, friction=0.5, thickness=0.01)
        scene.add_plane((0, -0.2, 0), (0, 1, 0), friction=0.5, thickness=0.01)
        sim = tcloth.Simulator(scene, "projective", dt=1 / 60, linear_solver=solver)
        for _ in range(60):
            sim.step()
            x = sim.positions()
            assert np.all(x[:, 1] >= -0.2 + 0.005)
            assert np.all(np.linalg.norm(x, axis=1) >= 0.2 + 0.005)
        assert sim.energy()["kinetic"] < 1e-3
        runs.append(x)
    assert np.abs(runs[0] - runs[1]).max() < 1e-3      # each solve to cg_tol = 1e-3


@pytest.mark.slow
def test_projective_converges_where_a_cloth_lands_on_a_collider(f64):
    """A cloth thrown down at 1 m/s onto a damped plane at dt 2e-3: the step in which it
    lands has a fixed point (the contact force is continuous where contact begins), so
    Liu's iterations converge there as at every other step (plain and accelerated); the
    cloth reaches the offset and stays in its outer half."""
    for anderson in (0, 5):
        scene = tcloth.Scene()
        scene.add_cloth(resolution=(8, 8), size=(0.5, 0.5), center=(0, 0.05, 0), pinned=[],
                        structural=(1e3, 0.5), shear=(1e2, 0.1), flexion=(10.0, 0.01))
        scene.add_plane((0, 0, 0), (0, 1, 0), friction=0.3, thickness=0.01)
        sim = tcloth.Simulator(scene, "projective", dt=2e-3, iterations=100,
                               anderson=anderson)
        thrown = sim.velocities()
        thrown[:, 1] = -1.0
        sim.set_state(velocities=thrown)
        residuals, lowest = [], []
        for _ in range(40):             # contact begins near step 20
            sim.step()
            residuals.append(sim.integrator.stats["residual"])
            lowest.append(sim.positions()[:, 1].min())
        assert max(residuals) < 1e-6, (anderson, max(residuals))
        assert 0.005 < min(lowest) < 0.01


def test_projectives_step_residual_is_the_steps_equation(f64):
    """``Projective.step_residual``: two particles on a damped spring, with air drag,
    falling: at any positions x it is m/h^2 (x0 + h v0 - x) + m g - c v + the spring's
    force at (x, v = (x - x0) / h), written out in NumPy; at the step's end, which the
    iterations converged, it is 0 to rounding."""
    k, kd, c, h, m = 50.0, 0.3, 0.02, 1 / 60, 0.2
    x0 = np.array([[0.0, 1.0, 0.0], [0.3, 1.1, 0.05]])
    v0 = np.array([[0.2, 0.0, -0.1], [0.0, 0.5, 0.3]])
    scene = tcloth.Scene(air_drag=c)
    scene.add_particles(x0, mass=m, velocities=v0)
    scene.add_springs([[0, 1]], k, kd, rest_length=0.25)
    sim = tcloth.Simulator(scene, "projective", dt=h, iterations=200, linear_solver="cg",
                           cg_tol=1e-12)
    with pytest.raises(tcloth.SceneError, match="take a step first"):
        sim.integrator.step_residual(x0)
    sim.step()
    with pytest.raises(tcloth.SceneError, match=r"shape \(2, 3\).*\(3, 3\)"):
        sim.integrator.step_residual(np.zeros((3, 3)))
    scale = m / h ** 2 * np.abs(sim.positions() - x0).max()
    assert np.abs(sim.integrator.step_residual(sim.positions())).max() < 1e-9 * scale
    x = x0 + h * v0 + np.random.default_rng(0).normal(0.0, 0.01, x0.shape)
    v = (x - x0) / h
    d = x[0] - x[1]
    length = np.linalg.norm(d)
    d /= length
    spring = -(k * (length - 0.25) + kd * (v[0] - v[1]) @ d) * d
    expected = m / h ** 2 * (x0 + h * v0 - x) + m * np.array(scene.gravity) - c * v
    expected += np.array([spring, -spring])
    np.testing.assert_allclose(sim.integrator.step_residual(x), expected, rtol=1e-12,
                               atol=1e-12 * np.abs(expected).max())


@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["backward_euler", "projective"])
def test_static_equilibrium_matches_a_long_explicit_run(f64, integrator):
    def hanging():
        scene = tcloth.Scene(air_drag=0.05)      # damping time m/c = 0.056 s
        scene.add_cloth(resolution=(6, 6), size=(0.5, 0.5), mass=0.1, plane="xy",
                        structural=(300.0, 0.5), shear=(60.0, 0.2), flexion=(5.0, 0.05))
        return scene
    # both start each step from x0 + h v0: a cloth at rest in equilibrium is a fixed point
    options = ({"newton_tol": 1e-8, "cg_tol": 1e-10} if integrator == "backward_euler"
               else {"iterations": 10, "cg_tol": 1e-4})
    implicit = tcloth.Simulator(hanging(), integrator, dt=1 / 30, **options)
    implicit.step(60)
    explicit = tcloth.Simulator(hanging(), "symplectic_euler", dt=5e-4)
    explicit.step(6000)
    # both are at rest: the residual kinetic energy bounds how far each is from equilibrium
    for sim in (implicit, explicit):
        assert sim.energy()["kinetic"] < 1e-12
    assert np.abs(implicit.positions() - explicit.positions()).max() < 1e-5


def general_paths():
    """Cloth, a list spring and a sphere: explicit, backward Euler and projective steps on
    the general (adjacency) paths, with the tolerance each gets."""
    scene = tcloth.Scene(air_drag=0.01)
    scene.add_cloth(resolution=(7, 7), size=(0.6, 0.6), center=(0, 0.3, 0), pinned=[],
                    structural=(3e3, 0.5), shear=(600.0, 0.1), flexion=(50.0, 0.01))
    scene.add_springs([[0, 48]], stiffness=5.0)
    scene.add_sphere((0, 0, 0), 0.2, friction=0.4, thickness=0.01)
    out = []
    # solvers converged far below their stopping tolerances, so that rounding in the
    # order of parallel sums cannot change an iteration count
    for integrator, dt, options, tol in (
            ("symplectic_euler", 1e-3, {}, 1e-12),
            ("backward_euler", 1 / 60, {"cg_tol": 1e-10, "newton_tol": 1e-10}, 1e-9),
            ("projective", 1 / 60, {"cg_tol": 1e-10, "cg_max_iterations": 1000}, 1e-9)):
        sim = tcloth.Simulator(scene, integrator, dt=dt, **options)
        sim.step(4)
        out.append((sim.positions(), tol))
    return out


def grid_paths():
    """The multigrid paths (9 x 9: two levels) of both implicit solvers."""
    grid = tcloth.Scene(air_drag=0.01)
    grid.add_cloth(resolution=(9, 9), size=(0.6, 0.6), structural=(3e3, 0.5),
                   shear=(600.0, 0.1), flexion=(50.0, 0.01))
    out = []
    # Newton without line search: near convergence the line search compares energies
    # equal to rounding, and the order of parallel sums can flip its decision
    for integrator, options in (("projective", {}),
                                ("backward_euler", {"cg_tol": 1e-12, "line_search": False,
                                                    "newton_iterations": 3})):
        sim = tcloth.Simulator(grid, integrator, dt=1 / 60, **options)
        sim.step(4)
        out.append((sim.positions(), 1e-12))
    return out


@pytest.mark.slow
@pytest.mark.parametrize("paths", [general_paths, grid_paths])
def test_parallel_loops_give_the_serial_results(paths):
    """Loops below init(serial_below=...) items run on one thread, so the tests mostly see
    serial code: the same steps with every loop parallel agree to rounding."""
    try:
        tcloth.init(arch="cpu", precision="f64")
        serial = paths()
        tcloth.init(arch="cpu", precision="f64", serial_below=0)
        parallel = paths()
    finally:
        tcloth.init(arch="cpu", precision="f64", serial_below=tcloth.runtime.SERIAL_BELOW)
    for (a, tol), (b, _) in zip(serial, parallel, strict=True):
        assert np.abs(a - b).max() < tol


def test_block_jacobi_cg_on_an_indefinite_matrix_stops_with_a_descent_direction(f64):
    """linalg.PCG on A = diag(d) + a spring chain's Laplacian (scalars, the same for x, y
    and z), preconditioned by a fixed positive diagonal: A positive definite is solved;
    A indefinite stops CG at the first direction of non-positive curvature with x a
    descent direction that lowers 1/2 x.A x - b.x; A negative definite stops it at once
    with x = P^-1 b."""
    from tcloth.integrators import linalg
    n = 8
    rng = np.random.default_rng(2)
    w = rng.uniform(1.0, 3.0, n - 1)                     # spring s joins s and s + 1
    # adjacency entries (particle, spring, other particle), sorted by particle
    entries = sorted([(s, s, s + 1) for s in range(n - 1)]
                     + [(s + 1, s, s) for s in range(n - 1)])
    start = np.searchsorted([p for p, _, _ in entries], np.arange(n + 1)).astype(np.int32)

    def field(values, dtype=ti.f64):
        f = ti.field(dtype, shape=len(values))
        f.from_numpy(np.asarray(values))
        return f
    adj = ti.Vector.field(2, ti.i32, shape=len(entries))
    adj.from_numpy(np.array([(s, q) for _, s, q in entries], dtype=np.int32))
    laplacian = np.zeros((n, n))
    for s in range(n - 1):
        laplacian[np.ix_([s, s + 1], [s, s + 1])] += w[s] * np.array([[1, -1], [-1, 1]])
    precond = rng.uniform(0.1, 0.3, n)
    b = rng.normal(size=(n, 3))

    def solve(d):
        cg = linalg.PCG(n, field(d), field(w[[s for _, s, _ in entries]]),
                        field(start, ti.i32), adj, field(precond), field(np.ones(n)))
        cg.b.from_numpy(b)
        iterations, residual = cg.solve(1e-12, 100)
        return iterations, residual, cg.x.to_numpy(), np.diag(d) + laplacian
    iterations, residual, x, a = solve(rng.uniform(1.0, 2.0, n))
    assert residual < 1e-12 and np.allclose(x, np.linalg.solve(a, b), rtol=0, atol=1e-10)
    iterations, residual, x, a = solve(np.full(n, -3.0))
    eig = np.linalg.eigvalsh(a)
    assert eig.min() < 0.0 < eig.max()
    assert 1 < iterations < 100 and residual > 1e-12
    assert np.sum(b * x) > 0.0 and 0.5 * np.sum(x * (a @ x)) - np.sum(b * x) < 0.0
    iterations, residual, x, _ = solve(np.full(n, -20.0))
    assert iterations == 1 and residual == 1.0
    assert np.allclose(x, precond[:, None] * b, rtol=0, atol=1e-14)
