"""Batches of substeps (``tcloth/batch.py``): n steps in one kernel launch give the same
numbers as n steps from Python, bit for bit (the same ``ti.func``s do the same arithmetic),
for every explicit integrator, VBD and XPBD with every in-kernel term (the triangle
membrane's: tests/test_membrane.py) and with self-collision (the batch stops where the
contact stage needs Python); a bad step inside a batch is named and the state before it
kept, as between single steps."""
import numpy as np
import pytest

import tcloth
from tcloth.errors import InstabilityError


def every_term_scene(colliders=True):
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0), air_drag=0.01)
    cloth = scene.add_cloth(resolution=(8, 8), size=(1.0, 1.0), center=(0.0, 1.0, 0.0),
                            pinned=[(0, 0), (7, 0)])
    scene.add_springs([cloth.particles[[0, 7], [7, 7]]], stiffness=50.0, damping=0.1)
    scene.set_wind((1.0, 0.0, 0.5), gust={"amplitude": (2.0, 0.0, 0.0), "frequency": 3.0,
                                          "phase": 0.1})
    scene.add_attraction(1e-3)
    if colliders:
        scene.add_sphere((0.1, 0.705, 0.0), 0.3, friction=0.3)
        scene.add_plane((0.0, 0.2, 0.0), (0.0, 1.0, 0.0), friction=0.5)
    scene.limit_strain(0.02)
    return scene


def run(integrator, batch, before, after, dt, colliders=True, **options):
    """Steps of dt in chunks ``before``, then of dt / 2 in chunks ``after``."""
    sim = tcloth.Simulator(every_term_scene(colliders), integrator, dt=dt, batch=batch,
                           **options)
    assert (sim.fusion() is None) == batch
    for n in before:
        sim.step(n)
    sim.set_dt(dt / 2)
    for n in after:
        sim.step(n)
    return sim


@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["forward_euler", "symplectic_euler", "verlet", "rk4"])
def test_a_batch_equals_single_steps_bit_for_bit(f32, integrator):
    dt = 2e-4 if integrator == "forward_euler" else 1e-3
    single = run(integrator, False, [1] * 8, [1] * 32, dt)
    # uneven batches, a change of dt between them (the time is computed in the kernel)
    batched = run(integrator, True, [7, 1], [20, 12], dt)
    assert batched.num_steps == single.num_steps == 40
    assert batched.time == single.time
    assert np.array_equal(batched.positions(), single.positions())
    assert np.array_equal(batched.velocities(), single.velocities())
    # the sphere's contact and the strain limit were at work
    assert single.energy()["contact"] > 0.0 and single.max_strain() < 0.03
    assert np.array_equal(batched.forces(), single.forces())


def falling_pair(batch, integrator, dt):
    """Two 10 x 10 cloths with self-collision falling at 6 m/s onto a box: at dt = 1e-3
    the guard corrects pairs, searches steps' motions and the box cuts paths (``sim``;
    ``start(sim)`` starts it again)."""
    scene = tcloth.Scene()
    for centre in ((0.0, 0.3, 0.0), (0.02, 0.35, 0.01)):
        scene.add_cloth(resolution=(10, 10), size=(0.5, 0.5), center=centre, plane="xz",
                        mass=0.1, structural=(400.0, 0.05), shear=(80.0, 0.02),
                        flexion=(10.0, 0.005), pinned=[])
    scene.add_box((0.0, -0.05, 0.0), (0.2, 0.05, 0.2), thickness=0.005)
    scene.set_self_collision(thickness=0.01)
    sim = tcloth.Simulator(scene, integrator, dt=dt, batch=batch)
    start_falling(sim)
    return sim


def start_falling(sim):
    sim.reset()
    sim.set_state(velocities=np.tile([0.0, -6.0, 0.0], (sim.scene.num_particles, 1)))


@pytest.mark.slow
def test_a_batch_with_self_collision_equals_single_steps_bit_for_bit(f32):
    """With self-collision a batch stops at each step that needs the contact stage from
    Python (a rebuild, a pair to correct, a path the box cut), which finishes that step:
    the same numbers and the same counts as single steps (one simulator run twice, so
    that the stage's kernels compile once), with symplectic Euler, the shipped
    self-contact scenes' integrator (every explicit integrator's batch without
    self-collision, RK4's four forces a step among them: the test above). A batch whose
    end then fails the stored energy's check runs its steps again one at a time from its
    start: each counted once, as single steps count them (the check made to fail at the
    first step whose pairs the guard corrected without a rebuild, in both runs)."""
    counts = ("guard_corrections", "rebuilds", "swept_searches", "collider_paths_cut",
              "failsafe_steps")
    sim = falling_pair(False, "symplectic_euler", 1e-3)
    before, corrected = sim.contact_stats(), []
    for _ in range(300):
        sim.step()
        now = sim.contact_stats()
        if now["guard_corrections"] > before["guard_corrections"] and \
                now["rebuilds"] == before["rebuilds"]:
            corrected.append(sim.num_steps - 1)
        before = now
    single = sim.positions(), sim.velocities(), sim.contact_stats()
    start_falling(sim)
    sim.set_batching(True)
    assert sim.fusion() is None
    for n in (7, 93, 150, 50):
        sim.step(n)
    assert sim.num_steps == 300
    assert np.array_equal(sim.positions(), single[0])
    assert np.array_equal(sim.velocities(), single[1])
    stats = single[2], sim.contact_stats()
    assert [stats[0][k] for k in counts] == [stats[1][k] for k in counts]
    assert min(stats[0][k] for k in counts[:4]) > 0, stats[0]

    verify = sim._checker.verify
    sim._checker.verify = lambda state, step, *piece: (
        InstabilityError("made to fail", step) if step == corrected[0]
        else verify(state, step, *piece))
    ends = []
    for batching in (False, True):
        start_falling(sim)
        sim.set_batching(batching)
        with pytest.raises(InstabilityError, match="made to fail"):
            sim.step(300)
        ends.append((sim.num_steps, sim.positions(), sim.contact_stats()))
    assert ends[0][0] == ends[1][0] == corrected[0]
    assert np.array_equal(ends[0][1], ends[1][1])
    replayed = ("guard_corrections", "swept_searches", "collider_paths_cut", "failsafe_steps")
    assert [ends[0][2][k] for k in replayed] == [ends[1][2][k] for k in replayed]
    assert ends[1][2]["guard_corrections"] > 0


@pytest.mark.slow
def test_xpbd_batches_where_it_projects_nothing(f32):
    """XPBD's step runs in a batch where it has no projections to run from Python (no
    self-contact; colliders act inside its iterations): bit for bit the single steps,
    with colliders and substeps (counted by "auto" too: one iteration a substep, the
    explicit limit 1.07e-3 s, so 4 substeps at dt = 4e-3 and 2 at 2e-3); with
    self-contact it says why not."""
    for substeps, dt, options in ((1, 1e-3, {}), (3, 1e-3, {}),
                                  ("auto", 4e-3, {"iterations": 1})):
        single = run("xpbd", False, [1] * 8, [1] * 32, dt, substeps=substeps, **options)
        batched = run("xpbd", True, [7, 1], [20, 12], dt, substeps=substeps, **options)
        if substeps == "auto":
            assert single.integrator.stats["substeps"] == 2
        assert batched.time == single.time
        assert np.array_equal(batched.positions(), single.positions())
        assert np.array_equal(batched.velocities(), single.velocities())
        assert single.max_strain() < 0.03
        # the cloth starts inside the sphere's offset surface (radius 0.3, thickness
        # 0.005) and the iterations pushed it out
        def gap(x):
            return (np.linalg.norm(x - (0.1, 0.705, 0.0), axis=1) - 0.305).min()
        assert gap(single.scene.positions) < -1e-4 and gap(single.positions()) > -1e-5
    scene = every_term_scene()
    scene.set_self_collision(thickness=0.01)
    assert "projects" in tcloth.Simulator(scene, "xpbd", dt=1e-3).fusion()


@pytest.mark.slow
def test_vbd_batches_without_colliders_or_self_contact(f32):
    """VBD's step runs in a batch where nothing in it needs Python (no colliders, no
    self-contact): bit for bit the single steps, with hinge bending, the adaptive initial
    guess (the gravity guess after a change from outside) and Chebyshev acceleration; with
    colliders it says why not."""
    def run_vbd(batch, before, after):
        scene = every_term_scene(colliders=False)
        scene.set_bending(1e-4)
        sim = tcloth.Simulator(scene, "vbd", dt=1e-3, batch=batch)
        assert (sim.fusion() is None) == batch
        for n in before:
            sim.step(n)
        sim.set_state(velocities=sim.velocities() * 0.5)
        sim.set_dt(5e-4)
        for n in after:
            sim.step(n)
        return sim

    single = run_vbd(False, [1] * 8, [1] * 12)
    batched = run_vbd(True, [5, 3], [7, 5])
    assert batched.time == single.time
    assert np.array_equal(batched.positions(), single.positions())
    assert np.array_equal(batched.velocities(), single.velocities())
    assert single.energy()["bending"] > 0.0
    sim = tcloth.Simulator(every_term_scene(), "vbd", dt=1e-3)
    assert "colliders" in sim.fusion()


@pytest.mark.slow
@pytest.mark.parametrize("self_collision", [False, True])
def test_a_bad_step_inside_a_batch_is_named_and_the_state_before_it_kept(f64,
                                                                         self_collision):
    def exploding(batch):
        scene = tcloth.Scene()
        scene.add_cloth(resolution=(6, 6), structural=(1e4, 0.0), shear=(1e4, 0.0),
                        flexion=(1e4, 0.0))
        if self_collision:
            scene.set_self_collision(thickness=0.02)
        sim = tcloth.Simulator(scene, "forward_euler", dt=1e-3, velocity_bound=50.0,
                               batch=batch)
        rng = np.random.default_rng(1)
        sim.set_state(velocities=rng.normal(0.0, 0.1, (36, 3)))
        with pytest.raises(InstabilityError) as err:
            sim.step(500)
        return sim, err.value
    single, single_err = exploding(False)
    batched, batched_err = exploding(True)
    assert 1 < batched_err.step < 500 and batched_err.step == single_err.step
    assert str(batched_err) == str(single_err)
    assert batched.num_steps == single.num_steps == batched_err.step - 1
    assert np.array_equal(batched.positions(), single.positions())
    assert np.array_equal(batched.velocities(), single.velocities())
    assert np.abs(batched.velocities()).max() <= 50.0
    if self_collision:      # the blow-up's steps outran the list: batches ended there
        assert batched.contact_stats()["rebuilds"] == single.contact_stats()["rebuilds"] > 1


@pytest.mark.slow
def test_fusion_names_what_keeps_a_scene_out_of_batches(f64):
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(4, 4))
    assert tcloth.Simulator(scene).fusion() is None
    assert "switched off" in tcloth.Simulator(scene, batch=False).fusion()
    assert "backward_euler" in tcloth.Simulator(scene, "backward_euler").fusion()
    sim = tcloth.Simulator(scene)            # the answer is kept, and follows live changes
    assert sim.fusion() is None
    sim.set_integrator("projective")
    assert "projective" in sim.fusion()
    sim.set_integrator("verlet")
    assert sim.fusion() is None
    gusty = tcloth.Scene()
    gusty.add_cloth(resolution=(4, 4))
    gusty.set_wind(gust=lambda t: (1.0, 0.0, 0.0))
    sim = tcloth.Simulator(gusty)
    assert "callable" in sim.fusion()
    sim.step(2)                     # per substep, the gust evaluated in Python each time
    assert sim.num_steps == 2
    scene.set_self_collision()          # the explicit integrators batch between its stops
    sim = tcloth.Simulator(scene)
    assert sim.fusion() is None
    sim.contact.record(True)          # a gradient's run: every step from Python
    assert "gradient" in sim.fusion()
    sim.contact.record(False)
    assert sim.fusion() is None
    assert "projects" in tcloth.Simulator(scene, "xpbd").fusion()
    assert "every iteration" in tcloth.Simulator(scene, "vbd").fusion()


def test_a_scene_whose_loops_run_on_several_threads_steps_from_python(f64):
    """Below serial_below items every loop runs on one thread and a batch takes the step;
    above, the loops run in parallel and a batch (one thread) would lose them."""
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(6, 6))
    try:
        tcloth.init(arch="cpu", precision="f64", serial_below=30)
        assert "36 particles" in tcloth.Simulator(scene).fusion()
    finally:
        tcloth.init(arch="cpu", precision="f64", serial_below=tcloth.runtime.SERIAL_BELOW)
    assert tcloth.Simulator(scene).fusion() is None
