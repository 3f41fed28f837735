"""The sandbox's logic without a window: the grab spring against closed forms, the
simulator's live setters against simulators built with the changed values, and the
viewer's Controls (picking, dragging, integrator switch, reset, instability)."""
import math

import numpy as np
import pytest

import tcloth
from tcloth.render.camera import Camera
from tcloth.viewer import Controls, OrbitCamera, pick


def one_particle(m=0.3):
    scene = tcloth.Scene(gravity=(0.0, 0.0, 0.0))
    scene.add_particles([[0.0, 0.0, 0.0]], mass=m)
    return scene


def cloth_scene(n=6, **extra):
    scene = tcloth.Scene(air_drag=1e-3)
    scene.add_cloth(resolution=(n, n), size=(0.5, 0.5), center=(0.0, 0.5, 0.0),
                    structural=(300.0, 0.05), shear=(60.0, 0.02), flexion=(8.0, 0.005),
                    pinned=[(0, 0), (n - 1, 0)])
    for key, args in extra.items():
        getattr(scene, key)(*args)
    return scene


def test_grab_spring_oscillates_as_a_harmonic_oscillator(f64):
    """A free particle pulled by an undamped grab spring moves as target + d cos(w t),
    w = sqrt(k/m), with energy()["grab"] = k/2 |x - target|^2 and the total conserved."""
    m, k, d = 0.3, 40.0, np.array([0.1, -0.05, 0.02])
    sim = tcloth.Simulator(one_particle(m), "rk4", dt=1e-3, grab=True)
    target = np.array([0.2, 0.4, -0.1])
    sim.set_state(positions=[target + d])
    sim.grab(0, target, stiffness=k, damping=0.0)
    e0 = sim.energy()
    assert e0["grab"] == pytest.approx(0.5 * k * d @ d, rel=1e-12)
    sim.step(700)
    w = math.sqrt(k / m)
    np.testing.assert_allclose(sim.positions()[0], target + d * math.cos(w * sim.time),
                               atol=1e-9)
    assert sim.energy()["total"] == pytest.approx(e0["total"], rel=1e-9)
    sim.release()
    v = sim.velocities()[0]
    sim.step(10)
    np.testing.assert_allclose(sim.velocities()[0], v, atol=1e-15)


def test_grab_spring_in_backward_euler_is_the_linear_closed_form(f64):
    """One backward Euler step of a particle on a damped grab spring solves
    (m/h^2 + c/h + k) x1 = m/h^2 (x0 + h v0) + c/h x0 + k target."""
    m, k, c, h = 0.3, 40.0, 0.7, 0.05
    x0, v0, target = np.array([0.1, 0.0, 0.0]), np.array([0.0, 1.0, 0.5]), np.zeros(3)
    sim = tcloth.Simulator(one_particle(m), "backward_euler", dt=h, grab=True, newton_tol=1e-12)
    sim.set_state(positions=[x0], velocities=[v0])
    sim.grab(0, target, stiffness=k, damping=c)
    sim.step()
    x1 = (m / h**2 * (x0 + h * v0) + c / h * x0 + k * target) / (m / h**2 + c / h + k)
    np.testing.assert_allclose(sim.positions()[0], x1, atol=1e-10)
    np.testing.assert_allclose(sim.velocities()[0], (x1 - x0) / h, atol=1e-8)


def test_grab_refuses_pinned_particles_and_plain_simulators(f64):
    scene = cloth_scene()
    with pytest.raises(tcloth.SceneError, match="grab=True"):
        tcloth.Simulator(scene).grab(7, (0, 0, 0))
    sim = tcloth.Simulator(scene, grab=True)
    with pytest.raises(tcloth.SceneError, match="particle 0 is pinned"):
        sim.grab(0, (0, 0, 0))
    with pytest.raises(tcloth.SceneError, match=r"particle must be .* \(got 36\)"):
        sim.grab(36, (0, 0, 0))
    sim.grab(7, (0, 1, 0))
    held = sim.grabbed
    assert held["stiffness"] == 300.0     # the structural springs' stiffness
    assert held["damping"] == pytest.approx(2 * math.sqrt(300.0 * scene.masses[7]))


def continue_like(sim, scene, integrator="symplectic_euler", steps=40, **settings):
    """Steps of a fresh simulator of ``scene`` from sim's state, and the same steps of sim."""
    ref = tcloth.Simulator(scene, integrator, dt=sim.dt, **settings)
    ref.set_state(sim.positions(), sim.velocities())
    ref.state.t = sim.state.t
    ref.step(steps)
    sim.step(steps)
    return ref.positions(), sim.positions()


@pytest.mark.slow_cases("projective", "symplectic_euler")
@pytest.mark.parametrize("integrator", ["symplectic_euler", "projective", "vbd", "xpbd"])
def test_live_parameters_act_as_a_scene_built_with_them(f64, integrator):
    """Springs, gravity, drag and wind changed live continue exactly as a simulator whose
    scene was built with those values (projective: its matrix is rebuilt)."""
    sim = tcloth.Simulator(cloth_scene(set_wind=((1.0, 0.0, 0.0),)), integrator, dt=2e-3)
    sim.step(20)
    sim.set_springs("structural", stiffness=900.0, damping=0.2)
    sim.set_springs("flexion", damping=0.0)
    sim.set_gravity((0.0, -3.0, 1.0))
    sim.set_air_drag(0.01)
    sim.set_wind((0.0, 0.0, 4.0))
    scene = tcloth.Scene(gravity=(0.0, -3.0, 1.0), air_drag=0.01)
    scene.add_cloth(resolution=(6, 6), size=(0.5, 0.5), center=(0.0, 0.5, 0.0),
                    structural=(900.0, 0.2), shear=(60.0, 0.02), flexion=(8.0, 0.0),
                    pinned=[(0, 0), (5, 0)])
    scene.set_wind((0.0, 0.0, 4.0))
    ref, got = continue_like(sim, scene, integrator)
    np.testing.assert_array_equal(got, ref)
    assert sim.scene.cloths[0].params["structural"] == (900.0, 0.2)


@pytest.mark.slow
def test_collider_and_strain_limit_switches(f64):
    """A collider switched off acts as absent (no force, energy, projection); switching
    strain limiting off acts as a scene without the limit."""
    def build(sphere, limit):
        scene = cloth_scene()
        if sphere:
            scene.add_sphere((0.0, 0.3, 0.1), 0.15)
        if limit:
            scene.limit_strain(0.02)
        return scene
    for integrator in ("symplectic_euler", "projective"):
        sim = tcloth.Simulator(build(True, True), integrator, dt=2e-3)
        sim.set_collider_enabled(0, False)
        sim.set_strain_limiting(False)
        ref, got = continue_like(sim, build(False, False), integrator, steps=150)
        np.testing.assert_array_equal(got, ref)
        assert sim.energy()["contact"] == 0.0
    sim.set_collider_enabled(0, True)
    assert sim.settings["colliders_off"] == []
    with pytest.raises(tcloth.SceneError, match=r"collider index must be in \[0, 1\) \(got 3\)"):
        sim.set_collider_enabled(3, False)


@pytest.mark.slow
def test_integrator_switch_and_dt_change_keep_the_state(f64):
    sim = tcloth.Simulator(cloth_scene(), "symplectic_euler", dt=2e-3)
    sim.step(25)
    x, v, t = sim.positions(), sim.velocities(), sim.time
    sim.set_integrator("rk4")
    sim.set_dt(1e-3)
    np.testing.assert_array_equal(sim.positions(), x)
    np.testing.assert_array_equal(sim.velocities(), v)
    assert sim.time == pytest.approx(0.05) and sim.integrator_name == "rk4"
    ref, got = continue_like(sim, cloth_scene(), "rk4")
    np.testing.assert_array_equal(got, ref)
    assert sim.time == pytest.approx(t + 40 * 1e-3, abs=1e-12)


@pytest.mark.slow
def test_checkpoint_keeps_live_changes(f64, tmp_path):
    """A simulator saved after live changes (springs, dt, a collider off, a held grab)
    loads and continues bit for bit."""
    scene = cloth_scene(add_sphere=((0.0, 0.3, 0.1), 0.15))
    sim = tcloth.Simulator(scene, dt=2e-3, grab=True)
    sim.step(10)
    sim.set_springs("shear", stiffness=150.0)
    sim.set_dt(1.5e-3)
    sim.set_collider_enabled(0, False)
    sim.grab(20, (0.3, 0.9, 0.2), stiffness=50.0)
    sim.step(5)
    sim.save(tmp_path / "live.npz")
    loaded = tcloth.Simulator.load(tmp_path / "live.npz")
    assert loaded.time == sim.time and loaded.grabbed["particle"] == 20
    sim.step(30)
    loaded.step(30)
    np.testing.assert_array_equal(loaded.positions(), sim.positions())


def screen_point(camera, p, aspect):
    """(u, v) in [0, 1] of point p seen by camera (perspective projection)."""
    c = Camera(camera.eye, camera.target, fov=camera.fov)
    d = p - c.eye
    half = math.tan(math.radians(c.fov) / 2)
    depth = d @ c.forward
    return (0.5 + 0.5 * (d @ c.right) / (depth * half * aspect),
            0.5 + 0.5 * (d @ c.up) / (depth * half))


def test_pick_and_drag_pull_the_particle_under_the_cursor(f64):
    sim = tcloth.Simulator(cloth_scene(), dt=2e-3, grab=True)
    controls = Controls(sim, substeps=5)
    camera = OrbitCamera(Camera((0.8, 1.2, 1.5), (0.0, 0.5, 0.0), fov=40.0))
    aspect = 1.6
    x = sim.positions()
    u, v = screen_point(camera, x[27], aspect)
    assert controls.start_drag(camera, u, v, aspect) == 27
    assert controls.start_drag(camera, 0.99, 0.99, aspect) is None
    controls.start_drag(camera, u, v, aspect)
    controls.drag(camera, u + 0.1, v + 0.05, aspect)
    target = sim.grabbed["target"]
    origin, direction = camera.ray(u + 0.1, v + 0.05, aspect)
    to_target = (target - origin) / np.linalg.norm(target - origin)
    np.testing.assert_allclose(to_target, direction, atol=1e-6)
    forward = camera.basis[0]
    assert (target - origin) @ forward == pytest.approx((x[27] - origin) @ forward)
    before = np.linalg.norm(x[27] - target)
    for _ in range(20):
        controls.advance()
    assert np.linalg.norm(sim.positions()[27] - target) < 0.5 * before
    controls.end_drag()
    assert sim.grabbed is None
    # pinned particles are never picked
    assert pick(x, controls.pickable, *camera.ray(*screen_point(camera, x[0], aspect),
                                                  aspect)) != 0


@pytest.mark.slow
def test_controls_apply_reset_and_instability(f64):
    sim = tcloth.Simulator(cloth_scene(limit_strain=(0.1,)), "forward_euler", dt=1e-3)
    controls = Controls(sim, substeps=10)
    assert set(controls.values["springs"]) == {"structural", "shear", "flexion"}
    assert controls.values["strain_limiting"] is True
    controls.values["springs"]["structural"] = [20000.0, 0.0]
    controls.values["gravity"] = 5.0
    controls.values["strain_limiting"] = False
    controls.apply()
    assert sim.scene.gravity[1] == -5.0 and not sim.settings["strain_limiting"]
    assert sim.scene.cloths[0].params["structural"] == (20000.0, 0.0)
    for _ in range(200):
        if not controls.advance():
            break
    assert controls.paused and "forward Euler" in controls.message
    assert np.all(np.isfinite(sim.positions()))
    assert controls.advance() is False
    controls.set_integrator("backward_euler")
    controls.paused = False
    assert controls.advance() and not controls.message
    controls.reset()
    assert sim.time == 0.0 and controls.values == controls.initial
    np.testing.assert_array_equal(sim.positions(), sim.scene.positions)
    assert sim.scene.cloths[0].params["structural"] == (300.0, 0.05)
    assert sim.settings["strain_limiting"] and sim.scene.gravity[1] == -9.81
    stats = controls.stats()
    assert stats["integrator"] == "backward_euler"
    assert stats["max_strain"] == pytest.approx(0.0, abs=1e-9)
