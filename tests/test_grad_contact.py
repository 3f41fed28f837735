"""Gradients through self-contact (``tcloth.grad`` over each forward step's contacts,
frozen: tcloth/grad/frozen.py): a cloth lying on another against central differences of
the simulator's own trajectories, in float64, with symplectic and backward Euler; the
adjoint's contact terms against the simulator's; the guard's projection against its log
replayed in NumPy; projective dynamics' self-contact projection against central
differences of its own kernel; the steps the gradient does not take reported; the
separating planes' normals and margins (either choice) against central differences."""
import warnings

import numpy as np
import pytest
import taichi as ti

import tcloth
from tcloth import grad
from tcloth.contact import projection, stage
from tcloth.contact.normals import SURFACE, chosen_margin, vertex_normals
from tcloth.contact.search import EDGE_EDGE
from tcloth.grad import frozen, projected
from tcloth.terms.self_contact import ProjectionLog

from conftest import check_gradients, check_step_terms, use_runtime

STEPS = 60
DT = {"symplectic_euler": 5e-4, "backward_euler": 5e-3, "projective": 5e-3}
# projective dynamics converged (its gradient is the converged step's): 100 iterations
# with Anderson acceleration leave the steps' residuals below 5e-13 (100 plain ones: up
# to 2.3e-5; 400 plain ones: 2e-13)
OPTIONS = {"backward_euler": {"newton_tol": 1e-12, "cg_tol": 1e-10, "newton_iterations": 100},
           "projective": {"iterations": 100, "anderson": 5, "cg_tol": 1e-12}}
THICKNESS = 0.01


def _stack():
    """A 5 x 5 cloth (turned 0.4 rad about the vertical: no edge parallel to one below)
    lying 9.8 mm above a 6 x 6 cloth held at its corners, within the 10 mm contact
    thickness, with friction 0.3."""
    scene = tcloth.Scene(air_drag=0.02, air_damping=0.3)
    springs = {"structural": (300.0, 0.5), "shear": (100.0, 0.2), "flexion": (50.0, 0.1)}
    scene.add_cloth(resolution=(6, 6), size=(0.25, 0.25), center=(0.0, 0.0, 0.0),
                    pinned=[(0, 0), (5, 0), (0, 5), (5, 5)], **springs)
    c, s = np.cos(0.4), np.sin(0.4)
    scene.add_cloth(resolution=(5, 5), size=(0.15, 0.15), center=(0.01, 0.0098, -0.005),
                    rotation=[[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]], **springs)
    scene.set_self_collision(thickness=THICKNESS, friction=0.3, stiffness=500.0)
    return scene


def _prepared(integrator):
    use_runtime("f64", __name__)
    scene = _stack()
    trajectory = grad.Trajectory(scene, steps=STEPS, dt=DT[integrator], integrator=integrator,
                                 checkpoint_every=7, **OPTIONS.get(integrator, {}))
    rng = np.random.default_rng(1)
    n = scene.num_particles
    v0 = 0.02 * rng.standard_normal((n, 3))
    v0[scene.pinned] = 0.0
    trajectory.set("velocities", v0)
    loss = grad.TargetPositions(scene.positions + 0.01 * rng.standard_normal((n, 3)),
                                steps=[STEPS // 2, STEPS])
    return trajectory, loss, trajectory.gradient(loss)


@pytest.fixture(scope="module")
def prepared():
    """The module's runs (trajectory, loss, gradient) by integrator, each made on first
    use."""
    runs = {}

    def get(integrator):
        if integrator not in runs:
            runs[integrator] = _prepared(integrator)
        return runs[integrator]
    return get


@pytest.fixture(params=["symplectic_euler", "backward_euler"])
def run(request, prepared):
    return prepared(request.param)


@pytest.mark.slow
def test_gradients_through_self_contact_match_central_differences(f64, run):
    """Over 60 steps of the top cloth pressed on the lower one (contacts touching from the
    first step, the guard idle), the gradient along random directions (arrays) or of
    scalars against central differences: within 1e-5. The arrays' step is 1e-8 m: at
    1e-7 one direction of the positions crosses a change of the contact set (backward
    Euler: 1.7e-3 off at 1e-7, 7e-10 at 1e-8)."""
    trajectory, loss, result = run
    assert not result.guarded_steps
    trajectory.sim.reset()
    trajectory.sim.set_state(trajectory.value("positions"), trajectory.value("velocities"))
    touching = trajectory.sim.self_contacts()
    assert touching["point_triangle"] >= 10 and touching["edge_edge"] >= 5, touching
    check_gradients(trajectory, loss, result, ("positions", "velocities", "masses",
                                                "structural.stiffness", "gravity"),
                    np.random.default_rng(2), 1e-8)


@pytest.mark.slow
def test_the_adjoints_contact_terms_are_the_simulators(f64, run):
    """With the stage's contacts frozen into the adjoint: its force is the simulator's
    (symplectic Euler), its gradient of backward Euler's incremental potential vanishes at
    the simulator's step (to the Newton tolerance), and without the contacts it does
    not."""
    trajectory, _, _ = run
    sim, adj = trajectory.sim, trajectory.adjoint
    x, v = trajectory.value("positions"), trajectory.value("velocities")
    sim.reset()
    sim.set_state(x, v)
    record = trajectory.record
    record.start(keep=True)
    record.before(0)
    adj.set_contacts(record.rows[0])
    step = check_step_terms(trajectory, x, v)
    if step is None:
        return
    _, h, inertia = step
    free = trajectory.free
    ids, kinds = record.rows[0]
    adj.set_contacts((ids[:0], kinds[:0]))
    g = adj.evaluate(h, h)
    assert np.abs(g[free]).max() > 1e-3 * np.abs(inertia[free]).max()


def _replay(entries, inv_mass, x, v):
    """The guard's projection replayed in NumPy from its log (``projection.Log``): each
    correction moves its vertex pair onto its plane and, where it did, removes their
    approaching normal velocity."""
    pair, n, delta, da, db, w, stopped = entries[:7]
    x, v = x.copy(), v.copy()
    for k in range(len(w)):
        a, b = pair[k]
        for y, lam, on in ((x, (delta[k] - n[k] @ (x[a] - x[b])) / w[k], True),
                           (v, -(n[k] @ (v[a] - v[b])) / w[k], stopped[k])):
            if on:
                y[a] += inv_mass[a] * lam * da[k]
                y[b] += inv_mass[b] * lam * db[k]
    return x, v


def _thrown(trajectory, speed):
    """The trajectory's initial velocities with the top cloth thrown down at ``speed``."""
    v = trajectory.value("velocities")
    top = np.arange(len(v)) >= 36                # the second cloth's particles
    v[top, 1] = -speed
    return v


@pytest.mark.slow
def test_the_guards_projection_is_differentiated_as_its_corrections(f64, prepared):
    """The top cloth thrown down at 1.5 m/s: the guard's projection changes the first
    step. Its log replayed in NumPy from the solver's end of the step gives the guard's
    (x1, v1); ``pull_back`` is the transpose of that replay's Jacobian; the trajectory
    takes such steps as projected, not guarded (no warning), and its gradient over 8
    steps (the guard's planes differentiated through the step's start, the inverse
    masses through its corrections) matches central differences within 1e-5 (measured:
    1e-10 to 2e-7; with the planes frozen it missed by 4e-2)."""
    trajectory = prepared("backward_euler")[0]
    sim, stage = trajectory.sim, trajectory.sim.contact
    thrown = _thrown(trajectory, 1.5)
    sim.reset()
    sim.set_state(trajectory.value("positions"), thrown)
    sim.step(1)
    entries = stage.log.entries()
    assert len(entries[-1]) >= 3
    x1s, v1s = (f.to_numpy() for f in stage.solved)
    inv_mass = sim.model.inv_mass.to_numpy()
    x1, v1 = _replay(entries, inv_mass, x1s, v1s)
    np.testing.assert_allclose(x1, sim.positions(), rtol=0, atol=1e-12)
    np.testing.assert_allclose(v1, sim.velocities(), rtol=0, atol=1e-12)
    rng = np.random.default_rng(3)
    p, q, wx, wv = (rng.standard_normal(x1.shape) for _ in range(4))
    moved = _replay(entries, inv_mass, x1s + p, v1s + q)       # affine: exact differences
    forward = (wx * (moved[0] - x1)).sum() + (wv * (moved[1] - v1)).sum()
    xb, vb = frozen.pull_back(entries, inv_mass, wx, wv)[:2]
    assert abs((xb * p).sum() + (vb * q).sum() - forward) <= 1e-10 * abs(forward)
    v = trajectory.value("velocities")
    trajectory.set("velocities", thrown)
    trajectory.set_steps(8)
    n = len(v)
    loss = grad.TargetPositions(trajectory.value("positions")
                                + 0.01 * rng.standard_normal((n, 3)), steps=[4, 8])
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", tcloth.GradientWarning)
            result = trajectory.gradient(loss)
        assert 0 in result.projected_steps and not result.guarded_steps
        check_gradients(trajectory, loss, result, ("positions", "velocities", "masses"), rng,
                        1e-8)
    finally:
        trajectory.set("velocities", v)
        trajectory.set_steps(STEPS)


@pytest.mark.slow
def test_steps_the_gradient_does_not_take_are_reported(f64, prepared, monkeypatch):
    """The projection's Jacobi passes (the GPUs') keep no log: a step they change is
    guarded, and the gradient says which and warns."""
    monkeypatch.setattr(projection, "JACOBI", True)
    trajectory = prepared("backward_euler")[0]
    v = trajectory.value("velocities")
    trajectory.set("velocities", _thrown(trajectory, 1.5))
    trajectory.set_steps(4)
    try:
        with pytest.warns(tcloth.GradientWarning, match="guard changed"):
            result = trajectory.gradient(grad.TargetPositions(trajectory.value("positions"),
                                                              steps=[4]))
    finally:
        trajectory.set("velocities", v)
        trajectory.set_steps(STEPS)
    assert 0 in result.guarded_steps and not result.projected_steps


@pytest.mark.slow
def test_the_fail_safe_is_differentiated_as_its_cuts(f64, monkeypatch):
    """The guard's fail-safe alone (no projection rounds: ``stage.ROUNDS`` 0), the top
    cloth thrown at 6 m/s (12 mm a step of 2 ms, past its 9.8 mm gap): the step's
    truncation cuts vertices short of their dividing planes, the gradient takes it
    (``projected_steps``) through each vertex's plane, and positions, velocities and
    masses match central differences within 1e-5. Most cuts are by planes along the
    layers' normal (``normals.SURFACE``), differentiated through the vertex normals. Both
    cloths' heights carry 0.5 mm of noise: on a flat layer a vertex's planes tie, and an
    edge's two ends lie level along the layer's normal, so the dividing plane's extents
    tie; the minimum has a kink there, and central differences average its two sides."""
    use_runtime("f64", __name__)
    monkeypatch.setattr(stage, "ROUNDS", 0)
    scene = _stack()
    trajectory = grad.Trajectory(scene, steps=1, dt=2e-3, integrator="backward_euler",
                                 checkpoint_every=1, **OPTIONS["backward_euler"])
    x = trajectory.value("positions")
    x[:, 1] += 5e-4 * np.random.default_rng(7).standard_normal(len(x))
    trajectory.set("positions", x)
    trajectory.set("velocities", _thrown(trajectory, 6.0))
    rng = np.random.default_rng(3)
    loss = grad.TargetPositions(x + 0.01 * rng.standard_normal(x.shape), steps=[1])
    with warnings.catch_warnings():
        warnings.simplefilter("error", tcloth.GradientWarning)
        result = trajectory.gradient(loss)
    assert result.projected_steps == [0] and not result.guarded_steps
    assert trajectory.sim.contact_stats()["failsafe_vertices"] > 0
    kinds = trajectory.sim.contact.truncation_log.entries()[2]
    assert (kinds >= SURFACE).sum() > 10 and (kinds < SURFACE).sum() > 5
    check_gradients(trajectory, loss, result, ("positions", "velocities", "masses"), rng,
                    1e-8)


@pytest.mark.slow
def test_projectives_self_contact_projection_has_its_gradient(f64, prepared):
    """Projective dynamics on the stack over 60 steps of 5 ms: its self-contact projection
    corrects contacts at each step of the first segment (the record keeps the segment
    run last: steps 0-6; positions apart to the thickness, approaching velocity removed
    with friction), and the guard changes some steps after it. The
    projection's pull-back is the transpose of its own kernel's Jacobian (central
    differences of ``SelfContact.project`` from the solver's end of the first step,
    which ``projected.before`` recovers from the log), and the trajectory's gradient
    matches central differences within 1e-5 (measured 4.6e-8, 2.5e-9 and 1.2e-9 for
    positions, velocities and masses). A log too small for a step's corrections makes
    the step guarded, and the gradient says so."""
    trajectory, loss, result = prepared("projective")
    assert not result.guarded_steps and result.forward_residual < 1e-10
    record, sim = trajectory.record, trajectory.sim
    assert all(m in record.corrections for m in range(7))   # the first segment's steps
    assert result.projected_steps
    term = record.projection
    sim.reset()
    sim.set_state(trajectory.value("positions"), trajectory.value("velocities"))
    sim.step(1)
    entries = term.log.entries()
    x1 = projected.before(entries, sim.positions())
    v1 = projected.before(entries, sim.velocities(), velocities=True)

    def project(x, v):          # over the list the stage holds now, without a refresh
        state = sim.state
        state.x.from_numpy(x)
        state.v.from_numpy(v)
        term.project(state.x, state.v, 0.0)
        return sim.positions(), sim.velocities()
    x2, v2 = project(x1, v1)
    entries = term.log.entries()
    assert set(entries[2]) == {0, 1}        # position and velocity corrections
    # velocity corrections along an edge pair's vertex normals (``contact_normal``): the
    # pull-back goes through the normals at x1 (``projected.vertex_normals_vjp``)
    assert ((entries[2] == 1) & (entries[1] == EDGE_EDGE + SURFACE)).any()
    np.testing.assert_array_equal(projected.before(entries, x2), x1)
    np.testing.assert_array_equal(projected.before(entries, v2, velocities=True), v1)
    rng = np.random.default_rng(4)
    p, q, wx, wv = (rng.standard_normal(x1.shape) for _ in range(4))
    eps = 1e-7
    (xa, va), (xb, vb) = project(x1 + eps * p, v1 + eps * q), project(x1 - eps * p, v1 - eps * q)
    fd = ((wx * (xa - xb)).sum() + (wv * (va - vb)).sum()) / (2 * eps)
    inv_mass = sim.model.inv_mass.to_numpy()
    x_bar, v_bar, _ = trajectory._projection.pull_back(entries, inv_mass, x1, wx, wv)
    assert abs((x_bar * p).sum() + (v_bar * q).sum() - fd) <= 1e-6 * abs(fd)
    check_gradients(trajectory, loss, result, ("positions", "velocities", "masses"),
                    np.random.default_rng(2), 1e-7)
    term.log = ProjectionLog(4)             # fewer than most steps' corrections
    term.log.on[None] = 1
    try:
        with pytest.warns(tcloth.GradientWarning, match="more corrections than its log"):
            guarded = trajectory.gradient(loss).guarded_steps
    finally:
        term.record(True)                   # its full size again
    assert 0 in guarded


@ti.kernel
def _plane_sum(table: ti.template(), ids: ti.template(), kind: ti.template(),
               choice: ti.i32, x: ti.template(), normals: ti.template(),
               wn: ti.template(), wd: ti.template(), out: ti.template()):
    vertex_normals(table, x, normals)
    for c in range(ids.shape[0]):
        n, d0, delta = chosen_margin(ids[c], kind[c], choice, x, table.params[0], normals)
        if d0 > 0.0:
            out[None] += wn[c].dot(n) + wd[c] * delta


@pytest.mark.parametrize("choice", [0, SURFACE])
def test_a_planes_normal_and_margin_have_their_gradient(f64, choice):
    """The separating planes of the stack's candidates (heights with 0.2 mm of noise), as
    the adjoints rebuild them at the step's start (``normals.chosen_margin``): along the
    closest points' direction, and along the surfaces' normal (the triangle's, or an edge
    pair's summed vertex normals, which depend on the vertices' neighbours). Taichi's
    reverse mode of sum_c wn_c . n_c + wd_c delta_c matches central differences within
    1e-6 relative (measured 4e-10 for the surfaces' at a step of 1e-8)."""
    scene = _stack()
    sim = tcloth.Simulator(scene, "backward_euler", dt=2e-3)
    broad = sim.contact.broad
    rows = broad.count
    ids = ti.Vector.field(4, ti.i32, shape=rows)
    kind = ti.field(ti.i32, shape=rows)
    ids.from_numpy(broad.candidates.ids.to_numpy()[:rows])
    kind.from_numpy(broad.candidates.kind.to_numpy()[:rows])
    n = scene.num_particles
    x, normals = (ti.Vector.field(3, ti.f64, shape=n, needs_grad=True) for _ in range(2))
    wn = ti.Vector.field(3, ti.f64, shape=rows)
    wd = ti.field(ti.f64, shape=rows)
    out = ti.field(ti.f64, shape=(), needs_grad=True)
    rng = np.random.default_rng(0)
    wn.from_numpy(rng.standard_normal((rows, 3)))
    wd.from_numpy(rng.standard_normal(rows))
    x0 = scene.positions.astype(np.float64) + 2e-4 * rng.standard_normal((n, 3))
    table = sim.contact.table

    def value(positions):
        x.from_numpy(positions)
        out[None] = 0.0
        _plane_sum(table, ids, kind, choice, x, normals, wn, wd, out)
        return out[None]
    value(x0)
    x.grad.fill(0)
    normals.grad.fill(0)
    out.grad[None] = 1.0
    _plane_sum.grad(table, ids, kind, choice, x, normals, wn, wd, out)
    d = rng.standard_normal((n, 3))
    adjoint = float((x.grad.to_numpy() * d).sum())
    fd = (value(x0 + 1e-8 * d) - value(x0 - 1e-8 * d)) / 2e-8
    assert rows > 100
    assert abs(adjoint - fd) <= 1e-6 * abs(fd), (adjoint, fd)
