"""Simulator API: instability handling, bad arguments, state access."""
import numpy as np
import pytest

import tcloth
from tcloth import InstabilityError, SceneError
from conftest import random_network


def stiff_cloth():
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(6, 6), structural=(1e6, 0.0), shear=(1e5, 0.0), flexion=None)
    return scene


def test_instability_error_names_step_time_integrator_and_keeps_last_good_state(f64):
    sim = tcloth.Simulator(stiff_cloth(), "forward_euler", dt=1 / 60)
    last_good = sim.positions()
    with pytest.raises(InstabilityError) as info:
        for _ in range(10_000):
            last_good = sim.positions()
            sim.step()
    err = info.value
    assert err.integrator == "forward_euler" and err.step == sim.num_steps + 1
    assert np.isclose(err.time, err.step / 60)
    msg = str(err)
    assert f"step {err.step}" in msg and "forward_euler" in msg and "Hint" in msg
    assert np.all(np.isfinite(sim.positions()))
    assert np.array_equal(sim.positions(), last_good)
    with pytest.raises(InstabilityError):
        sim.step()
    assert np.array_equal(sim.positions(), last_good)


def test_stable_small_dt_runs_same_stiff_cloth(f64):
    sim = tcloth.Simulator(stiff_cloth(), "symplectic_euler", dt=2e-5)
    sim.step(200)
    assert np.isclose(sim.time, 200 * 2e-5)
    assert sim.max_strain() < 0.01


@pytest.mark.parametrize("kwargs,argument", [
    (dict(dt=0.0), "dt"),
    (dict(dt=-1e-3), "dt"),
    (dict(dt=float("nan")), "dt"),
    (dict(integrator="euler"), "integrator"),
    (dict(newton_iterations=3), "newton_iterations"),
    (dict(position_bound=0.0), "position_bound"),
])
def test_bad_simulator_arguments(f64, kwargs, argument):
    with pytest.raises(SceneError, match=argument):
        tcloth.Simulator(random_network(n=3, seed=0), **kwargs)


def test_set_state_validates_and_round_trips(f64):
    scene = random_network(n=4, seed=1)
    sim = tcloth.Simulator(scene)
    x = np.arange(12.0).reshape(4, 3)
    sim.set_state(positions=x, velocities=-x)
    assert np.array_equal(sim.positions(), x) and np.array_equal(sim.velocities(), -x)
    with pytest.raises(SceneError, match="positions"):
        sim.set_state(positions=np.zeros((3, 3)))
    with pytest.raises(SceneError, match="velocities"):
        sim.set_state(velocities=np.full((4, 3), np.nan))
    with pytest.raises(SceneError, match="n must be"):
        sim.step(-1)


@pytest.mark.slow
def test_reset_replays_a_fresh_run_and_takes_a_new_dt(f64):
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(4, 4), size=(0.3, 0.3), center=(0, 0.2, 0))
    scene.add_sphere((0, 0.08, 0), 0.1, velocity=(0, 2.0, 0))  # reaches the cloth: t matters
    fresh = tcloth.Simulator(scene, "verlet", dt=1e-3)
    fresh.step(50)
    sim = tcloth.Simulator(scene, "verlet", dt=5e-4)
    sim.step(30)
    sim.reset(dt=1e-3)
    assert sim.num_steps == 0 and sim.time == 0.0 and sim.state.t == 0.0
    sim.step(50)
    assert np.array_equal(sim.positions(), fresh.positions())
    assert np.array_equal(sim.velocities(), fresh.velocities())
    with pytest.raises(SceneError, match="dt"):
        sim.reset(dt=0.0)


def test_free_fall_matches_closed_form(f64):
    g = np.array([0.0, -9.81, 0.0])
    scene = tcloth.Scene(gravity=g)
    scene.add_particles([[0.0, 10.0, 0.0]], velocities=[[1.0, 2.0, 0.0]])
    sim = tcloth.Simulator(scene, "verlet", dt=1e-2)
    sim.step(100)
    expected = np.array([0, 10, 0]) + np.array([1, 2, 0]) * 1.0 + 0.5 * g * 1.0 ** 2
    assert np.allclose(sim.positions()[0], expected, atol=1e-12)
    e = sim.energy()
    assert np.isclose(e["total"], 0.5 * 5.0 + 9.81 * 10.0, rtol=1e-12)
    assert e["total"] == pytest.approx(e["kinetic"] + e["gravity"] + e["spring"] + e["contact"])


def test_pinned_particles_stay_put(f64):
    scene = tcloth.Scene()
    cloth = scene.add_cloth(resolution=(5, 5), pinned=[(0, 0), (4, 0)])
    sim = tcloth.Simulator(scene, dt=1e-4)
    sim.step(50)
    pins = cloth.particles[0, [0, 4]]
    assert np.array_equal(sim.positions()[pins], scene.positions[pins])
    assert np.all(sim.positions()[cloth.particles[1:, 2], 1] < scene.positions[cloth.particles[1:, 2], 1])


def launches(monkeypatch, sim, steps):
    """The names of tcloth's kernels launched by sim.step(steps), in order."""
    from taichi.lang.kernel_impl import Kernel
    names, call = [], Kernel.__call__

    def counted(kernel, *args, **kwargs):
        if kernel.func.__module__.startswith("tcloth"):
            names.append(kernel.func.__name__)
        return call(kernel, *args, **kwargs)
    monkeypatch.setattr(Kernel, "__call__", counted)
    sim.step(steps)
    monkeypatch.undo()
    return names


def built(sim):
    """The classes of the terms the simulator's integrator evaluates, and whether it has a
    strain limiter: what its kernels can compile at all."""
    return [type(t).__name__ for t in sim.integrator.forces.terms], sim._limiter is not None


@pytest.mark.slow
def test_absent_features_are_neither_built_nor_launched(f64, monkeypatch):
    plain = tcloth.Scene()
    plain.add_cloth(resolution=(4, 4), flexion=None)
    sim = tcloth.Simulator(plain, dt=1e-4, batch=False)
    assert built(sim) == (["GravityDrag", "Springs"], False)
    # per step: one launch for every term's force, the update, the instability check
    # (the springs' energy and strain, then the particles'), then the end copied into the
    # start's State (a step is checked before it is kept)
    assert launches(monkeypatch, sim, 3) == ["_launch", "_phase", "spring_sums",
                                             "check_state", "_copy_state"] * 3
    full = tcloth.Scene()
    cloth = full.add_cloth(resolution=(4, 4))
    full.add_springs([cloth.particles[[0, 3], [0, 3]]], stiffness=1.0)
    full.set_wind((1, 0, 0))
    full.add_attraction(1e-3)
    full.add_sphere((0, 0, 0), 0.1)
    full.limit_strain(0.1)
    full.set_self_collision()
    sim = tcloth.Simulator(full, dt=1e-4, grab=True, batch=False)
    assert built(sim) == (["GravityDrag", "Springs", "Wind", "Attraction", "Colliders",
                           "SelfContact", "Grab"], True)
    names = launches(monkeypatch, sim, 3)
    # self-contact needs Python between its kernels: the terms before it share a launch,
    # it launches its own, Grab (after it in the sum's order) gets another
    for name in ("self_contact_forces", "_limit_pass", "_correct_velocities"):
        assert name in names
    assert names.count("_launch") == 6


@pytest.mark.slow
def test_a_batch_is_one_launch_for_every_substep(f64, monkeypatch):
    """step(n) of an explicit integrator: one launch for the n substeps (each checked for
    its particles' kinetic and gravitational energy inside it), then the check of the
    last state's stored energy and strain: the same launches for 20 substeps as for 40."""
    scene = tcloth.Scene(gravity=(0, -9.81, 0))
    scene.add_cloth(resolution=(5, 5), pinned=[(0, 0)])
    scene.add_sphere((0, -0.3, 0), 0.2)
    scene.limit_strain(0.1)
    for integrator in ("forward_euler", "symplectic_euler", "verlet", "rk4"):
        sim = tcloth.Simulator(scene, integrator, dt=1e-4)
        assert sim.fusion() is None
        names = launches(monkeypatch, sim, 20)
        assert names[0] == "run" and names.count("run") == 1 and names[-1] == "check_state"
        assert launches(monkeypatch, sim, 40) == names
        assert sim.num_steps == 60


@pytest.mark.slow_cases("f32")
@pytest.mark.parametrize("precision", ["f32", "f64"])
def test_state_copies_equal_the_fields(precision):
    """positions(), velocities() and forces() (one copy kernel each) give the fields'
    values in the working precision, as Taichi's own to_numpy does."""
    tcloth.init(arch="cpu", precision=precision)
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(5, 7))
    sim = tcloth.Simulator(scene)
    sim.step(3)
    for copy, field in ((sim.positions, sim.state.x), (sim.velocities, sim.state.v),
                        (sim.forces, sim.state.f)):
        got, expected = copy(), field.to_numpy()
        assert got.dtype == expected.dtype == np.dtype("float32" if precision == "f32"
                                                       else "float64")
        assert got.shape == (35, 3) and np.array_equal(got, expected)
        assert np.abs(expected).max() > 0
