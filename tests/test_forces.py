"""Forces against independent references: finite differences and a NumPy spring network."""
import numpy as np
import pytest

import tcloth
from conftest import energy_gradient, numpy_forces, random_network


def test_spring_force_is_minus_energy_gradient(f64):
    scene = random_network(n=6, seed=1, velocity_scale=0.0)
    sim = tcloth.Simulator(scene)
    x0 = scene.positions
    force = sim.forces()
    grad = energy_gradient(sim, x0, "spring")
    assert np.allclose(force, -grad, rtol=1e-6, atol=1e-6 * np.abs(force).max())


def test_forces_match_numpy_reference_with_damping_gravity_and_drag(f64):
    scene = random_network(n=9, seed=2, kd=(1.5), gravity=(0.3, -9.81, 0.1))
    scene.air_drag = 0.25
    sim = tcloth.Simulator(scene)
    rng = np.random.default_rng(3)
    x = scene.positions + 0.1 * rng.normal(size=(9, 3))
    v = rng.normal(size=(9, 3))
    sim.set_state(positions=x, velocities=v)
    expected = numpy_forces(scene, x, v)
    assert np.allclose(sim.forces(), expected, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("families, free_particle", [
    (dict(), False),
    (dict(), True),              # the grid does not hold every particle
    (dict(shear=None), False),
    (dict(flexion=None), False),
    (dict(structural=None, shear=(30.0, 0.3)), False),
])
def test_grid_stencil_matches_spring_list(f64, families, free_particle):
    scene = tcloth.Scene(gravity=(0, -9.81, 0), air_drag=0.3)
    params = dict(structural=(500.0, 0.2), shear=(100.0, 0.1), flexion=(20.0, 0.05))
    cloth = scene.add_cloth(resolution=(7, 6), size=(1.2, 0.8), **{**params, **families})
    extra = cloth.particles[[0, 4], [0, 6]]
    scene.add_springs([extra], stiffness=7.0, damping=0.1)
    if free_particle:
        scene.add_particles([[0.3, 1.5, 0.2]], mass=0.5)
        scene.add_springs([[cloth.particles[2, 3], scene.num_particles - 1]], stiffness=9.0)
    rng = np.random.default_rng(4)
    x = scene.positions + 0.02 * rng.normal(size=(scene.num_particles, 3))
    v = rng.normal(size=x.shape)
    forces = []
    for stencil in (True, False):
        sim = tcloth.Simulator(scene, grid_stencil=stencil)
        assert sim.model.list_spring_count == ((1 + free_particle) if stencil
                                               else scene.num_springs)
        sim.set_state(positions=x, velocities=v)
        forces.append(sim.forces())
    assert np.allclose(forces[0], forces[1], rtol=1e-12, atol=1e-10)
    assert np.allclose(forces[0], numpy_forces(scene, x, v), rtol=1e-12, atol=1e-10)


def test_float32_is_the_default_precision():
    tcloth.init(arch="cpu")
    scene = random_network(n=5, seed=5)
    sim = tcloth.Simulator(scene)
    assert sim.positions().dtype == np.float32
    f = sim.forces()
    ref = numpy_forces(scene, scene.positions.astype(np.float32).astype(np.float64), scene.velocities)
    assert np.allclose(f, ref, rtol=1e-4, atol=1e-4 * np.abs(ref).max())


@pytest.mark.parametrize("value", [-1, 2.5, True, "many"])
def test_bad_serial_below_is_refused(value):
    with pytest.raises(tcloth.SceneError, match="serial_below"):
        tcloth.init(arch="cpu", serial_below=value)


def test_reinit_makes_old_simulators_refuse_to_run():
    tcloth.init(arch="cpu")
    sim = tcloth.Simulator(random_network(n=4, seed=6))
    tcloth.init(arch="cpu", precision="f64")
    with pytest.raises(tcloth.StaleSimulatorError, match="tcloth.init"):
        sim.step()
    with pytest.raises(RuntimeError):
        sim.positions()
