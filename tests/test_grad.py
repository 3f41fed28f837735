"""Gradients through the simulation (tcloth.grad) against central finite differences of
the simulator's own trajectories, in float64; one backward Euler step's adjoint against its
Jacobian formed column by column, one projective step's along random directions; the
adjoint's kernels against the simulator's terms."""
import warnings

import numpy as np
import pytest

import tcloth
from tcloth import grad

from conftest import check_gradients, check_step_terms, use_runtime

STEPS = 60
# the integrators' options: converged steps, whose derivative the adjoint gives
OPTIONS = {"backward_euler": {"newton_tol": 1e-12, "cg_tol": 1e-10},
           "projective": {"iterations": 100, "cg_tol": 1e-3}}


def _cloth(collider):
    """A 6 x 6 cloth held at two corners, with hinge bending (warp and weft), a membrane
    (stretch and shear) and a gusty wind (no lift: its |u| v_t has a kink where the wind turns along the cloth), over a
    sphere it touches (collider) or free."""
    scene = tcloth.Scene(air_drag=0.02, air_damping=0.3)
    scene.add_cloth(resolution=(6, 6), size=(0.3, 0.3), center=(0.0, 0.105, 0.0),
                    structural=(300.0, 0.5), shear=(100.0, 0.2), flexion=(50.0, 0.1),
                    pinned=[(0, 0), (5, 0)])
    scene.set_bending((4e-4, 2e-4))
    scene.set_membrane(stretch=(200.0, 150.0), shear=20.0, damping=0.1)
    scene.set_wind(velocity=(1.0, 0.2, 2.0), drag=0.6, tangential=0.05,
                   gust={"amplitude": (0.5, 0.0, 0.3), "frequency": 3.0})
    if collider:
        scene.add_sphere((0.0, 0.0, 0.0), 0.1, friction=0.3)
    return scene


def _trajectory(integrator, steps=STEPS, checkpoint_every=7):
    scene = _cloth(collider=True)
    trajectory = grad.Trajectory(scene, steps=steps, dt=2e-3, integrator=integrator,
                                 checkpoint_every=checkpoint_every,
                                 **OPTIONS.get(integrator, {}))
    rng = np.random.default_rng(1)
    n = scene.num_particles
    loss = grad.TargetPositions(scene.positions + 0.01 * rng.standard_normal((n, 3)),
                                steps=[steps // 2, steps])
    trajectory.set("controls", 0.05 * rng.standard_normal((steps, len(trajectory.pinned), 3)))
    return trajectory, loss


def _prepared(integrator, steps=STEPS):
    use_runtime("f64", __name__)
    trajectory, loss = _trajectory(integrator, steps)
    return trajectory, loss, trajectory.gradient(loss)


@pytest.fixture(scope="module")
def symplectic_euler():
    """The module's symplectic Euler trajectory (on the sphere), its loss and gradient."""
    return _prepared("symplectic_euler")


@pytest.fixture(scope="module")
def backward_euler():
    """The module's backward Euler trajectory (on the sphere), its loss and gradient."""
    return _prepared("backward_euler")


@pytest.fixture(scope="module")
def projective():
    """The module's projective dynamics trajectory (on the sphere from its first step: the
    contacts' onsets, where its iterations used to cycle, are inside the window), half as
    long as the others' (its steps iterate to 1e-8)."""
    return _prepared("projective", STEPS // 2)


@pytest.fixture(params=["symplectic_euler", "backward_euler", "projective"])
def run(request):
    return request.getfixturevalue(request.param)


@pytest.fixture(params=["symplectic_euler", "backward_euler"])
def differenced(request):
    return request.getfixturevalue(request.param)


@pytest.mark.slow
def test_every_parameters_gradient_matches_central_differences(f64, differenced):
    """Each parameter kind over 60 steps with the pinned corners driven and particles on a
    frictional sphere (a contact set the small differences leave unchanged): the
    gradient's component (scalars) or its directional derivative along a random direction
    (arrays) against central differences. Projective dynamics' adjoint: its step's
    Jacobian test, its springs' gravity gradient and its contacts' (test_grad_contact.py)."""
    trajectory, loss, result = differenced
    rng = np.random.default_rng(2)
    trajectory.forward(loss)
    assert trajectory.sim.contact_stats()["collider"] >= 3      # particles on the sphere
    assert result.unconverged_steps == []
    check_gradients(trajectory, loss, result, trajectory.names, rng, 1e-7)


@pytest.mark.slow
def test_checkpoints_change_the_memory_not_the_gradient(f64, symplectic_euler):
    """Every state stored against one checkpoint per 20 steps: the same gradient (the
    segments run again step for step), a third of the memory."""
    trajectory, loss, _ = symplectic_euler
    kept = trajectory.checkpoint_every
    results = []
    try:
        for every in (1, 20):
            trajectory.checkpoint_every = every
            results.append(trajectory.gradient(loss))
    finally:
        trajectory.checkpoint_every = kept
    for name, value in results[0].grad.items():
        np.testing.assert_array_equal(results[1].grad[name], value)
    assert results[0].loss == results[1].loss
    assert results[1].memory_bytes < results[0].memory_bytes / 2


def _one_step(trajectory, x0, v0, directions, step, rng):
    """One step of the trajectory's simulator from (x0, v0): the adjoint of the loss
    w . (x1, v1) (w random) along each column d of ``directions`` (D^T J^T w) and the
    central differences of the simulator's step along them ((J D)^T w), and the result."""
    sim, n = trajectory.sim, trajectory.scene.num_particles
    wx, wv = rng.standard_normal((n, 3)), rng.standard_normal((n, 3))
    loss = grad.Loss(1, lambda _, x, v: (float((wx * x).sum() + (wv * v).sum()), wx, wv))
    kept = {name: trajectory.value(name) for name in ("positions", "velocities", "controls")}
    steps = trajectory.steps
    try:
        trajectory.set("controls", None)
        trajectory.set_steps(1)
        trajectory.set("positions", x0)
        trajectory.set("velocities", v0)
        result = trajectory.gradient(loss, wrt=["positions", "velocities"])

        def run(state):
            sim.reset()                 # time 0, as the trajectory's step (a gust reads it)
            sim.set_state(state[:3 * n].reshape(n, 3), state[3 * n:].reshape(n, 3))
            sim.step(1)
            return np.concatenate([sim.positions().ravel(), sim.velocities().ravel()])

        state = np.concatenate([x0.ravel(), v0.ravel()])
        jd = np.stack([(run(state + step * d) - run(state - step * d)) / (2.0 * step)
                       for d in directions.T], axis=1)
    finally:
        trajectory.set_steps(steps)
        for name, value in kept.items():
            trajectory.set(name, value)
    adjoint = np.concatenate([result.grad["positions"].ravel(),
                              result.grad["velocities"].ravel()])
    return directions.T @ adjoint, jd.T @ np.concatenate([wx.ravel(), wv.ravel()]), result


@pytest.mark.slow
def test_a_backward_euler_steps_adjoint_is_its_jacobians_transpose(f64, backward_euler):
    """One step of the module's cloth from a disturbed state: its Jacobian d(x1, v1)/d(x0,
    v0) formed column by column by central differences of the simulator's step; J^T (w_x,
    w_v) against the adjoint of the loss w_x . x1 + w_v . v1."""
    trajectory, _, _ = backward_euler
    n = trajectory.scene.num_particles
    rng = np.random.default_rng(3)
    x0 = trajectory.value("positions") + 0.01 * rng.standard_normal((n, 3))
    v0 = 0.3 * rng.standard_normal((n, 3))
    adjoint, expected, _ = _one_step(trajectory, x0, v0, np.eye(6 * n), 1e-6, rng)
    np.testing.assert_allclose(adjoint, expected, rtol=1e-6, atol=1e-6 * np.abs(expected).max())


@pytest.mark.slow
def test_projective_steps_left_unconverged_are_named_and_warned_of(f64, projective):
    """Three iterations a step instead of a hundred: steps are left above forward_tol, the
    gradient names them and warns that it is not the run's; with forward_tol above the
    largest residual, none are named and nothing is warned of."""
    trajectory, loss, _ = projective
    sim, tols = trajectory.sim, (trajectory.forward_tol, trajectory.adjoint_tol)
    sim.set_integrator_options(iterations=3)
    trajectory.adjoint_tol = 1e-2          # what is tested is the naming, not the solve
    try:
        with pytest.warns(tcloth.GradientWarning, match="above forward_tol"):
            result = trajectory.gradient(loss, wrt=["gravity"])
        worst = result.forward_residual
        assert worst > trajectory.forward_tol
        assert result.unconverged_steps == sorted(set(result.unconverged_steps))
        assert 0 < len(result.unconverged_steps) <= trajectory.steps
        assert 0 <= result.unconverged_steps[0] and result.unconverged_steps[-1] < trajectory.steps
        trajectory.forward_tol = 2.0 * worst
        with warnings.catch_warnings():
            warnings.simplefilter("error", tcloth.GradientWarning)
            again = trajectory.gradient(loss, wrt=["gravity"])
        assert again.unconverged_steps == [] and again.forward_residual == worst
    finally:
        trajectory.forward_tol, trajectory.adjoint_tol = tols
        sim.set_integrator_options(iterations=OPTIONS["projective"]["iterations"])


@pytest.mark.slow
def test_a_projective_steps_adjoint_is_its_jacobians_transpose(f64, projective):
    """One projective step from a state on the sphere, disturbed: J^T (w_x, w_v) from the
    adjoint against directional derivatives of the simulator's step J d by central
    differences, along six random directions d."""
    trajectory, _, _ = projective
    n = trajectory.scene.num_particles
    rng = np.random.default_rng(3)
    x0 = trajectory.value("positions") + 0.002 * rng.standard_normal((n, 3))
    v0 = trajectory.value("velocities") + 0.1 * rng.standard_normal((n, 3))
    adjoint, expected, result = _one_step(trajectory, x0, v0,
                                          rng.standard_normal((6 * n, 6)), 1e-7, rng)
    assert result.forward_residual < 1e-9
    np.testing.assert_allclose(adjoint, expected, rtol=1e-6)


@pytest.mark.slow
def test_the_adjoints_kernels_are_the_simulators_terms(f64, run):
    """The explicit adjoint's force is the simulator's force; the implicit one's gradient
    vanishes at the simulator's backward Euler step and its Jacobian (by differences) is
    the integrator's Hessian; projective dynamics' residual vanishes at its step, its
    friction kernel gives the step's velocities, and its reverse mode is the transpose of
    its Jacobian by differences."""
    trajectory, _, _ = run
    sim, adj = trajectory.sim, trajectory.adjoint
    rng = np.random.default_rng(4)
    n = sim.model.particle_count
    x = trajectory.value("positions") + 0.003 * rng.standard_normal((n, 3))
    v = 0.1 * rng.standard_normal((n, 3))
    sim.reset()                         # time 0 (the gust reads it)
    sim.set_state(x, v)
    step = check_step_terms(trajectory, x, v)
    if step is None:
        return
    x1, h, _ = step
    free = trajectory.free
    if trajectory.projective:
        assert sim.integrator.stats["residual"] < 1e-9
        np.testing.assert_array_equal(adj.evaluate(h, h, friction=True), sim.velocities())
    p = rng.standard_normal((n, 3))
    p[trajectory.pinned] = 0.0
    parts = []
    for sign in (1.0, -1.0):
        adj.set_inputs(x, v, x1 + sign * 1e-6 * p)
        parts.append(adj.evaluate(h, h))
    fd = (parts[0] - parts[1]) / 2e-6
    if trajectory.projective:
        w = rng.standard_normal((n, 3))
        w[trajectory.pinned] = 0.0
        adj.set_inputs(x, v, x1)
        transposed = adj.vjp(w, h, h)[2]
        assert abs((transposed * p).sum() - (w * fd).sum()) <= 1e-7 * abs((w * fd).sum())
        return
    integ = sim.integrator
    adj.set_inputs(x, v, x1)
    integ.potential.begin(adj.x, adj.v, h, 0.0, trajectory._x_start)
    trajectory._rhs.from_numpy(p)
    hp = integ.hessian_product(adj.x1, trajectory._rhs, h, h)
    np.testing.assert_allclose(hp[free], fd[free], rtol=0, atol=1e-6 * np.abs(fd).max())


@pytest.mark.parametrize("what", ["attraction", "moving collider", "callable gust",
                                  "integrator"])
def test_what_it_does_not_differentiate_is_named(f64, what):
    """Scenes and integrators the adjoint does not cover raise SceneError naming what."""
    scene = _cloth(collider=False)
    integrator = "symplectic_euler"
    if what == "attraction":
        scene.add_attraction(1e-3)
    elif what == "callable gust":
        scene.set_wind(velocity=(1.0, 0.0, 0.0), gust=lambda t: (0.0, 0.0, 0.1 * t))
    elif what == "moving collider":
        scene.add_sphere((0.0, 0.0, 0.0), 0.1, velocity=(0.0, 0.1, 0.0))
    else:
        integrator = "xpbd"
    with pytest.raises(tcloth.SceneError, match="attraction|moving|gust|xpbd"):
        grad.Trajectory(scene, steps=2, dt=1e-3, integrator=integrator)


@pytest.mark.slow_cases("backward_euler")
@pytest.mark.parametrize("integrator", ["symplectic_euler", "backward_euler"])
def test_a_wind_along_the_cloths_normal_has_its_gradient(f64, integrator):
    """A flat cloth at rest, the wind blowing along its normal: the wind's speed along the
    cloth is exactly 0 at the first step, where its norm's derivative is 0/0 (the gradient
    was NaN); the wind's and the positions' against central differences within 1e-5."""
    scene = tcloth.Scene(air_drag=0.02)
    scene.add_cloth(resolution=(5, 5), size=(0.2, 0.2), center=(0.0, 0.5, 0.0),
                    pinned=[(0, 0), (4, 0)])
    scene.set_wind(velocity=(0.0, -2.0, 0.0), drag=0.6, tangential=0.05)
    trajectory = grad.Trajectory(scene, steps=10, dt=1e-3, integrator=integrator,
                                 **OPTIONS.get(integrator, {}))
    loss = grad.TargetPositions(scene.positions + 0.01, steps=[10])
    result = trajectory.gradient(loss)
    assert np.isfinite(result.grad["wind"]).all()
    rng = np.random.default_rng(4)
    check_gradients(trajectory, loss, result, ["positions"], rng, 1e-7)
    check_gradients(trajectory, loss, result, ["wind"], rng, 1e-6)


def test_a_loss_written_as_a_taichi_kernel_is_differentiated_by_its_reverse_mode(
        f64, symplectic_euler):
    """grad.KernelLoss: a nonlinear kernel's value and gradient against the closed form;
    the module's symplectic Euler trajectory differentiated through a kernel of its
    loss (1/2 |x - target|^2 at the same steps) gives the NumPy loss's gradient; a
    function that is not a kernel is refused by name."""
    import taichi as ti
    trajectory, loss, result = symplectic_euler
    n = trajectory.scene.num_particles
    target = ti.Vector.field(3, ti.f64, shape=n)
    target.from_numpy(loss.targets)

    @ti.kernel
    def squared(x: ti.template(), v: ti.template(), out: ti.template()):
        for p in x:
            out[None] += 0.5 * (x[p] - target[p]).norm_sqr()

    @ti.kernel
    def curved(x: ti.template(), v: ti.template(), out: ti.template()):
        for p in x:
            out[None] += x[p].y ** 3 * v[p].norm_sqr() + ti.sin(x[p].x)

    rng = np.random.default_rng(7)
    x, v = rng.standard_normal((n, 3)), rng.standard_normal((n, 3))
    value, dx, dv = grad.KernelLoss(curved, 0, n).evaluate(0, x, v)
    speed2 = (v * v).sum(axis=1)
    assert value == pytest.approx(float((x[:, 1] ** 3 * speed2 + np.sin(x[:, 0])).sum()),
                                  rel=1e-13)
    expected_dx = np.zeros_like(x)
    expected_dx[:, 0] = np.cos(x[:, 0])
    expected_dx[:, 1] = 3.0 * x[:, 1] ** 2 * speed2
    np.testing.assert_allclose(dx, expected_dx, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(dv, 2.0 * x[:, 1:2] ** 3 * v, rtol=1e-13, atol=1e-13)
    kernel_result = trajectory.gradient(grad.KernelLoss(squared, loss.steps, n))
    assert kernel_result.loss == pytest.approx(result.loss, rel=1e-12)
    for name in trajectory.names:
        np.testing.assert_allclose(kernel_result.grad[name], result.grad[name], rtol=1e-10,
                                   atol=1e-12 * np.abs(result.grad[name]).max())
    with pytest.raises(tcloth.SceneError, match="kernel must be a Taichi kernel"):
        grad.KernelLoss(lambda x, v, out: None, 0, n)
    with pytest.raises(tcloth.SceneError, match=r"n = 36 particles \(got x of shape \(2, 3\)"):
        grad.KernelLoss(squared, 0, n).evaluate(0, np.zeros((2, 3)), np.zeros((2, 3)))


def test_the_fabric_fits_measurements_have_their_gradients():
    """``tcloth.testing.specimens``' measurements of a specimen scene (grad.ChordAngle on the
    strips, grad.DrapeCoefficient inside the disc's projected rim, the bias strip's
    extension) and a measured loss against central differences of positions (NumPy: no
    simulation); the chord angle of a straight strip against its closed form."""
    from tcloth.testing.specimens import Specimens
    specimens = Specimens(tcloth.scene.fabric.preset("denim"), cells=8, rings=4)
    rng = np.random.default_rng(5)
    x = specimens.scene.positions + 0.01 * rng.standard_normal(
        (specimens.scene.num_particles, 3))
    direction = rng.standard_normal(x.shape)
    measures = specimens.measures(0, targets=rng.standard_normal(6))
    plus, minus = x + 1e-7 * direction, x - 1e-7 * direction
    fd = (specimens.measure(plus) - specimens.measure(minus)) / 2e-7
    analytic = [float((m.measure(x)[1] * direction).sum()) for m in measures]
    np.testing.assert_allclose(analytic, fd, rtol=1e-5, atol=1e-7)
    loss = grad.Sum(*measures)
    fd = (loss.evaluate(0, plus, None)[0] - loss.evaluate(0, minus, None)[0]) / 2e-7
    assert float((loss.evaluate(0, x, None)[1] * direction).sum()) == pytest.approx(fd, 1e-5)
    dc = specimens.measure(x)[4]
    assert 0.0 < dc < 1.5
    # a straight chord 30 degrees below the horizontal along z, tip edge of two points
    y = np.zeros((3, 3))
    y[1:] = [[0.01, -0.5, np.sqrt(0.75)], [-0.01, -0.5, np.sqrt(0.75)]]
    assert grad.ChordAngle(0, [1, 2], 2, 1).measure(y)[0] == pytest.approx(30.0, 1e-12)


def test_measured_losses_refuse_bad_arguments():
    """A measured loss's bad argument is a SceneError naming it and the value."""
    for make, match in (
            (lambda: grad.ChordAngle(0, [1], 1, 5), "axis must be 0 .x. or 2 .z., horizontal "
                                                     r"\(got 1\)"),
            (lambda: grad.ChordAngle(0, [], 0, 5), r"tip must be at least 1 particle ids"),
            (lambda: grad.DrapeCoefficient([0, 1], 0.15, 0.09, 5), "rim must be at least 3"),
            (lambda: grad.DrapeCoefficient([0, 1, 2], 0.15, 0.2, 5),
             r"support must be less than radius 0.15 m \(got 0.2\)"),
            (lambda: grad.DrapeCoefficient([0, 1, 2], 0.15, 0.09, 5, scale=0.0),
             r"scale must be > 0.0 \(got 0.0\)"),
            (lambda: grad.ChordAngle(0, [1], 0, 5, target=float("nan")),
             "target must be finite")):
        with pytest.raises(tcloth.SceneError, match=match):
            make()


@pytest.mark.slow
def test_the_fabric_fit_recovers_a_known_fabric():
    """tools/fit_fabric.py --quick (the test-sized specimens: cantilever strips of 8 cells,
    a disc of 5 rings, the bias strip; denim measured with 1 mm of noise, the fit started
    from fleece): the bending along warp and weft and the shear within 5 % of denim's."""
    import subprocess
    import sys
    from pathlib import Path
    tool = Path(__file__).resolve().parents[1] / "tools" / "fit_fabric.py"
    out = subprocess.run([sys.executable, str(tool), "--quick"], capture_output=True,
                         text=True, check=True).stdout
    errors = {line.split(".")[1]: float(line.split(":")[1]) for line in out.splitlines()
              if line.startswith("fit.") and ".relative_error:" in line}
    assert sorted(errors) == ["bending_warp", "bending_weft", "shear"], out
    assert max(errors.values()) < 0.05, out


@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["symplectic_euler", "backward_euler", "projective"])
def test_a_cloth_of_springs_alone(f64, integrator):
    """A scene with none of the features (springs, gravity and drag only: projective
    dynamics' one V-cycle a global step, no friction after it) compiles the adjoint
    without them; its gravity gradient against central differences."""
    scene = tcloth.Scene(air_drag=0.05)
    scene.add_cloth(resolution=(4, 4), size=(0.2, 0.2), structural=(200.0, 0.3),
                    shear=(50.0, 0.1), flexion=None)
    trajectory = grad.Trajectory(scene, steps=10, dt=2e-3, integrator=integrator,
                                 **OPTIONS.get(integrator, {}))
    assert integrator != "projective" or trajectory.sim.integrator.vcycles
    loss = grad.TargetPositions(scene.positions - 0.01, steps=10)
    result = trajectory.gradient(loss, wrt=["gravity"])
    direction = np.array([0.3, -1.0, 0.2])
    fd = trajectory.central_difference(loss, "gravity", direction, 1e-5)
    assert abs(float(result.grad["gravity"] @ direction) - fd) <= 1e-6 * abs(fd)
