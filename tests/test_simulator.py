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


FEATURE_KERNELS = {"springs": ("terms.springs", "eval_springs"),
                   "grid": ("terms.springs", "eval_grid_springs"),
                   "wind": ("terms.wind", "eval_wind"),
                   "attraction": ("terms.attraction", "eval_attraction"),
                   "colliders": ("terms.colliders", "collide"),
                   "strain": ("constraints", "_limit_pass"),
                   "self_contact": ("terms.self_contact", "self_contact_forces"),
                   "grab": ("terms.grab", "add_grab")}


def launches(monkeypatch, scene, steps=3, **settings):
    """Count the launches of each feature kernel over a few steps."""
    import importlib
    counts = dict.fromkeys(FEATURE_KERNELS, 0)
    for feature, (module, name) in FEATURE_KERNELS.items():
        mod = importlib.import_module(f"tcloth.{module}")
        kernel = getattr(mod, name)

        def counted(*args, _k=kernel, _f=feature):
            counts[_f] += 1
            return _k(*args)
        monkeypatch.setattr(mod, name, counted)
    tcloth.Simulator(scene, dt=1e-4, **settings).step(steps)
    return counts


def test_absent_features_launch_nothing(f64, monkeypatch):
    plain = tcloth.Scene()
    plain.add_cloth(resolution=(4, 4), flexion=None)
    assert launches(monkeypatch, plain) == {"springs": 0, "grid": 3, "wind": 0, "attraction": 0,
                                            "colliders": 0, "strain": 0, "self_contact": 0,
                                            "grab": 0}
    full = tcloth.Scene()
    cloth = full.add_cloth(resolution=(4, 4))
    full.add_springs([cloth.particles[[0, 3], [0, 3]]], stiffness=1.0)
    full.set_wind((1, 0, 0))
    full.add_attraction(1e-3)
    full.add_sphere((0, 0, 0), 0.1)
    full.limit_strain(0.1)
    full.set_self_collision()
    counts = launches(monkeypatch, full, grab=True)
    assert all(counts[f] >= 3 for f in FEATURE_KERNELS), counts
