"""Particle masses set live (``Simulator.set_masses``) against a simulator built with
them: the same steps bit for bit, whatever the integrator caches from the masses
(projective dynamics' constant matrix, the membrane's damping, the energy budget)."""
import numpy as np
import pytest

import tcloth


def _scene():
    scene = tcloth.Scene(air_drag=0.01, air_damping=0.5)
    scene.add_cloth(resolution=(6, 6), size=(0.3, 0.3), center=(0.0, 0.12, 0.0),
                    structural=(300.0, 0.5), shear=(100.0, 0.2), flexion=(50.0, 0.1),
                    pinned=[(0, 0), (5, 0)])
    scene.set_membrane(stretch=(200.0, 150.0), shear=20.0, damping=0.2)
    scene.add_sphere((0.0, 0.0, 0.0), 0.1, friction=0.3)
    return scene


@pytest.mark.slow
def test_masses_set_live_step_as_a_simulator_built_with_them(f64):
    """Masses varied over the cloth (up to 3 times the built ones): 20 projective steps at
    1/60 onto the sphere after ``set_masses`` equal, bit for bit, those of a simulator
    built from a scene with those masses; and they differ from the steps before the
    change."""
    integrator, scene = "projective", _scene()
    masses = scene.masses * np.linspace(1.0, 3.0, scene.num_particles)
    live = tcloth.Simulator(scene, integrator, dt=1 / 60)
    live.step(20)
    before = live.positions()
    live.reset()
    live.set_masses(masses)
    live.step(20)
    built_scene = _scene()
    built_scene.set_masses(masses)
    built = tcloth.Simulator(built_scene, integrator, dt=1 / 60)
    built.step(20)
    np.testing.assert_array_equal(live.positions(), built.positions())
    np.testing.assert_array_equal(live.velocities(), built.velocities())
    assert np.abs(live.positions() - before).max() > 1e-3


def test_bad_masses_name_the_argument_and_value(f64):
    """A mass that is not finite and positive, or an array of the wrong shape, is a
    SceneError naming ``masses`` (and the value), from the Scene and the live setter;
    the masses stay as they were."""
    scene = _scene()
    n, kept = scene.num_particles, scene.masses
    for bad, match in ((-1.0, r"masses must be finite and > 0.0 \(got masses = -1.0\)"),
                       (np.r_[kept[:-1], np.nan], rf"masses\[{n - 1}\] = nan"),
                       (np.zeros(n), r"masses\[0\] = 0.0"),
                       (np.ones(n + 1), rf"shape \({n},\) \(got shape \({n + 1},\)\)")):
        with pytest.raises(tcloth.SceneError, match=match):
            scene.set_masses(bad)
    sim = tcloth.Simulator(scene, "symplectic_euler", dt=1e-4)
    with pytest.raises(tcloth.SceneError, match="masses"):
        sim.set_masses(-2.0)
    np.testing.assert_array_equal(scene.masses, kept)
    np.testing.assert_array_equal(sim.model.mass.to_numpy(), kept)
