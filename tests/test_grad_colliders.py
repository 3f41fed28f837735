"""Gradients through the colliders' sweep (a path the contact stage cut where it entered a
collider, differentiated as the cut it is: ``tcloth/grad/sweep.py``) and through a cloth
resting on a frictional collider, against central differences of the simulator's own
trajectories in float64."""
import warnings

import numpy as np
import pytest

import tcloth
from tcloth import grad

from conftest import check_gradients, use_runtime

STEPS = 20


def _thrown(shape, speed, stiffness, integrator, dt):
    """A 5 x 5 cloth (16 cm) 3 cm above a collider, thrown down at ``speed`` and sideways
    at 0.3 m/s; a loss on its positions at the last step."""
    scene = tcloth.Scene(air_drag=0.02)
    scene.add_cloth(resolution=(5, 5), size=(0.16, 0.16), center=(0.0, 0.13, 0.0),
                    mass=0.05, structural=(300.0, 0.5), shear=(100.0, 0.2),
                    flexion=(50.0, 0.1), pinned=[])
    if shape == "sphere":
        scene.add_sphere((0.0, 0.0, 0.0), 0.1, friction=0.3, stiffness=stiffness)
    elif shape == "box":
        scene.add_box((0.0, 0.0, 0.0), (0.1, 0.1, 0.1), friction=0.3, stiffness=stiffness)
    else:
        scene.add_plane((0.0, 0.1, 0.0), (0.0, 1.0, 0.0), friction=0.3, stiffness=stiffness)
    options = {"backward_euler": {"newton_tol": 1e-12, "cg_tol": 1e-10,
                                  "adjoint_tol": 1e-12}}.get(integrator, {})
    trajectory = grad.Trajectory(scene, steps=STEPS, dt=dt, integrator=integrator,
                                 checkpoint_every=5, **options)
    v = trajectory.value("velocities")
    v[:, 0], v[:, 1] = 0.3, -speed
    trajectory.set("velocities", v)
    rng = np.random.default_rng(0)
    loss = grad.TargetPositions(scene.positions + 0.01 * rng.standard_normal((25, 3)),
                                steps=[STEPS])
    with warnings.catch_warnings():
        warnings.simplefilter("error", tcloth.GradientWarning)
        result = trajectory.gradient(loss)
    return trajectory, loss, result


def _check(trajectory, loss, result):
    """The initial positions and velocities (central differences' step 1e-8 m, m/s) and
    gravity (1e-6 m/s^2) along random directions."""
    rng = np.random.default_rng(3)
    check_gradients(trajectory, loss, result, ["positions", "velocities"], rng, 1e-8)
    check_gradients(trajectory, loss, result, ["gravity"], rng, 1e-6)


# (shape, speed m/s, the collider's stiffness, integrator, dt): symplectic Euler at 15 m/s
# moves 7.5 mm a step, through the 5 mm thickness into the collider; backward Euler's
# penalty, soft here, lets the cloth through at 4 m/s
CUT = [("sphere", 15.0, 1000.0, "symplectic_euler", 5e-4),
       ("box", 15.0, 1000.0, "symplectic_euler", 5e-4),
       ("sphere", 4.0, 100.0, "backward_euler", 1.0 / 120.0)]


@pytest.mark.slow
@pytest.mark.parametrize("case", CUT, ids=[f"{c[3]}-{c[0]}" for c in CUT])
def test_the_collider_sweeps_cuts_are_differentiated(case):
    """A cloth thrown into a collider: the steps whose paths the sweep cut are taken by
    the gradient (``projected_steps``), none is left out, and the initial positions and
    velocities and gravity match central differences within 1e-5 (without the cuts'
    adjoint the sphere's miss by factors of 0.2 to 7)."""
    use_runtime("f64", __name__)
    trajectory, loss, result = _thrown(*case)
    assert result.projected_steps and not result.guarded_steps
    assert trajectory.sim.contact_stats()["collider_paths_cut"] > 0
    _check(trajectory, loss, result)


@pytest.mark.slow
def test_a_cloth_resting_on_a_frictional_plane_has_its_gradient():
    """Backward Euler, a cloth landing on a plane (mu 0.3) and coming to rest on it: the
    friction's tangential speed is then exactly 0, where the norm's derivative is 0/0 (it
    was NaN, and the gradient 0); against central differences within 1e-5."""
    use_runtime("f64", __name__)
    trajectory, loss, result = _thrown("plane", 3.0, 1000.0, "backward_euler", 1.0 / 120.0)
    assert np.isfinite(result.grad["positions"]).all()
    _check(trajectory, loss, result)
