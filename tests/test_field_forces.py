"""Every field force under every integrator, against an explicit reference.

Wind (constant, with a sinusoidal gust, with a Python-callable gust), attraction and air
drag each act on a small scene for 20 steps of every integrator. The reference is RK4 at
a 20 times smaller step (drag: the closed form v0 exp(-c t / m)). The quantity compared
is what the force changes: the mean velocity for wind and drag (spring forces are
internal and cancel in it), the displacement for attraction. Every integrator is at least
first order: over 20 steps a first-order method misses a displacement from rest by about
1/20 of it, so each lands within 10 % of the change; a force an integrator dropped or
evaluated with the wrong wind misses by far more.
"""
import math

import numpy as np
import pytest

import tcloth
from conftest import use_runtime

INTEGRATORS = ["forward_euler", "symplectic_euler", "verlet", "rk4", "backward_euler",
               "projective", "vbd", "xpbd"]
DT, STEPS = 1e-3, 20


def gust(t):
    return (0.0, 8.0 + 40.0 * t, 0.0)


def wind_scene(**wind):
    """A horizontal 3 x 3 cloth in zero gravity under an upward wind."""
    scene = tcloth.Scene(gravity=(0, 0, 0))
    scene.add_cloth(resolution=(3, 3), size=(0.4, 0.4), mass=0.1, structural=(50.0, 0.1),
                    shear=(10.0, 0.05), flexion=None, pinned=[])
    scene.set_wind(drag=0.6, lift=0.2, tangential=0.05, **wind)
    return scene


def attraction_scene():
    scene = tcloth.Scene(gravity=(0, 0, 0))
    scene.add_particles([[0, 0, 0], [0.3, 0, 0], [0, 0.25, 0.1], [0.2, 0.2, -0.2]],
                        mass=[3.0, 1.0, 2.0, 1.5])
    scene.add_attraction(G=0.2, softening=0.01)
    return scene


def drag_scene():
    scene = tcloth.Scene(gravity=(0, 0, 0), air_drag=2.0)
    scene.add_particles([[0, 0, 0], [1, 0, 0]], mass=0.1, velocities=[[1, 2, 0], [0, -1, 3]])
    return scene


CASES = {
    "wind": (lambda: wind_scene(velocity=(0.5, 9.0, 0.0)), "mean_velocity"),
    "wind_sinusoid_gust": (lambda: wind_scene(velocity=(0.0, 6.0, 0.5), gust={
        "amplitude": (0.0, 4.0, 0.0), "frequency": 12.0, "phase": 0.3}), "mean_velocity"),
    "wind_callable_gust": (lambda: wind_scene(gust=gust), "mean_velocity"),
    "attraction": (attraction_scene, "displacement"),
    "drag": (drag_scene, "mean_velocity"),
}


def measure(sim, quantity, x_start):
    if quantity == "mean_velocity":
        return sim.velocities().mean(axis=0)
    return sim.positions() - x_start


def run(scene, integrator, dt, steps, quantity):
    options = {"linear_solver": "cg"} if integrator in ("backward_euler", "projective") \
        else {}
    if integrator == "backward_euler":
        options.update(newton_tol=1e-10, cg_tol=1e-10)
    if integrator == "projective":
        options.update(iterations=60, cg_tol=1e-10)
    sim = tcloth.Simulator(scene, integrator, dt=dt, **options)
    sim.step(steps)
    return measure(sim, quantity, scene.positions)


@pytest.fixture(scope="module")
def references():
    """name -> (reference, its change from the start), NumPy."""
    use_runtime("f64", __name__)
    out = {}
    for name, (make, quantity) in CASES.items():
        scene = make()
        if name == "drag":
            decay = math.exp(-2.0 / 0.1 * DT * STEPS)
            reference = (scene.velocities * decay).mean(axis=0)
        else:
            reference = run(scene, "rk4", DT / 20, 20 * STEPS, quantity)
        start = scene.velocities.mean(axis=0) if quantity == "mean_velocity" else 0.0
        out[name] = (reference, reference - start)
    return out


@pytest.mark.slow
@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_every_field_force_acts_under_every_integrator(f64, references, integrator):
    for name, (make, quantity) in CASES.items():
        got = run(make(), integrator, DT, STEPS, quantity)
        reference, change = references[name]
        error = np.abs(got - reference).max()
        assert error < 0.1 * np.abs(change).max(), (name, got, reference)


def test_backward_euler_takes_a_callable_gust(f64):
    """The gust callable's wind reaches backward Euler, not only the constant velocity: a
    gust-only wind lifts the cloth as it lifts it under symplectic Euler."""
    lifts = {}
    for integrator in ("symplectic_euler", "backward_euler"):
        sim = tcloth.Simulator(wind_scene(gust=lambda t: (0.0, 5.0, 0.0)), integrator, dt=DT)
        sim.step(10)
        lifts[integrator] = sim.velocities()[:, 1].mean()
    assert lifts["symplectic_euler"] > 0.05
    assert lifts["backward_euler"] == pytest.approx(lifts["symplectic_euler"], rel=0.05)
