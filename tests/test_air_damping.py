"""Air drag per particle (``air_drag`` c: force -c v) and per mass (``air_damping`` gamma:
force -gamma m v, the same at every resolution), against closed forms: a body under
gravity and linear drag k = c_p / m approaches the terminal speed g / k as
v(t) = g / k (1 - exp(-k t)); symplectic Euler's velocity obeys v1 = v0 + h (g - k v0) and
an implicit step's v1 = (v0 + h g) / (1 + h k), exactly for a free particle."""
import math

import numpy as np
import pytest

import tcloth
from tcloth.viewer import Controls

G = 9.81


def falling_particles(masses, air_drag=0.0, air_damping=0.0):
    """Free particles of the given masses side by side, at rest, under gravity -G y."""
    scene = tcloth.Scene(gravity=(0.0, -G, 0.0), air_drag=air_drag, air_damping=air_damping)
    x = np.zeros((len(masses), 3))
    x[:, 0] = np.arange(len(masses))
    scene.add_particles(x, mass=np.asarray(masses, dtype=float))
    return scene


def falling_cloth(n, mass=0.15, **drag):
    """The same 1 m x 1 m cloth of 0.15 kg (0.15 kg/m^2) at n x n particles, horizontal,
    free, at rest: it falls as one body (its springs stay at rest length)."""
    scene = tcloth.Scene(gravity=(0.0, -G, 0.0), **drag)
    scene.add_cloth(resolution=(n, n), size=(1.0, 1.0), center=(0.0, 1.0, 0.0), plane="xz",
                    mass=mass, structural=(5.0, 0.0), shear=None, flexion=None, pinned=[])
    return scene


def fall_speeds(sim, steps):
    """Each particle's downward speed after ``steps`` more steps from the scene's start."""
    sim.reset()
    sim.step(steps)
    return -sim.velocities()[:, 1]


def test_air_damping_gives_the_same_terminal_speed_at_16_and_64_particles_a_side(f64):
    """The issue's resolution test: the same cloth at 16 x 16 and 64 x 64 falls at
    g / gamma with air_damping gamma (within 2 % of the closed form and of each other, at
    2 s and at 0.3 s on the way there); with air_drag tuned to match at 16 x 16 the
    64 x 64 cloth (particles 16 times lighter) falls 16 times slower."""
    gamma, dt = 4.0, 1e-3
    m16 = 0.15 / 16 ** 2
    terminal, early = {}, {}
    old = {}
    for n in (16, 64):
        sim = tcloth.Simulator(falling_cloth(n, air_damping=gamma), "symplectic_euler", dt=dt)
        early[n] = fall_speeds(sim, 300)
        terminal[n] = fall_speeds(sim, 2000)
        sim.set_air_damping(0.0)
        sim.set_air_drag(gamma * m16)          # the same drag as gamma at 16 x 16
        old[n] = fall_speeds(sim, 2000)
    for n in (16, 64):
        assert np.ptp(terminal[n]) < 1e-9 * G / gamma
        assert terminal[n].mean() == pytest.approx(G / gamma, rel=0.02)
        assert early[n].mean() == pytest.approx(G / gamma * (1 - math.exp(-gamma * 0.3)),
                                                rel=0.02)
    assert terminal[64].mean() == pytest.approx(terminal[16].mean(), rel=0.02)
    assert early[64].mean() == pytest.approx(early[16].mean(), rel=0.02)
    # per particle: k = c / m_p is 16 times larger at 64 x 64, the terminal speed 16 times less
    assert old[16].mean() == pytest.approx(G / gamma, rel=0.02)
    assert old[64].mean() == pytest.approx(G / (16 * gamma), rel=0.02)


def test_air_drag_is_per_particle_and_air_damping_per_mass(f64):
    """Particles of 0.01, 0.1 and 1 kg: with air_drag c each has k = c / m, with
    air_damping gamma all have k = gamma, with both k = c / m + gamma; symplectic Euler's
    velocity is its recurrence v_n = g / k (1 - (1 - h k)^n) to rounding, within 1 % of
    the exact exp(-k t), and each particle's drag coefficient is c + gamma m."""
    masses, c, gamma, h, n = np.array([0.01, 0.1, 1.0]), 0.05, 2.0, 1e-3, 400
    sim = tcloth.Simulator(falling_particles(masses, air_drag=c), "symplectic_euler", dt=h)
    for drag, damping in ((c, 0.0), (0.0, gamma), (c, gamma)):
        sim.set_air_drag(drag)
        sim.set_air_damping(damping)
        np.testing.assert_array_equal(sim.scene.drag_coefficients(), drag + damping * masses)
        k = drag / masses + damping
        v = fall_speeds(sim, n)
        np.testing.assert_allclose(v, G / k * (1 - (1 - h * k) ** n), rtol=1e-10)
        np.testing.assert_allclose(v, G / k * (1 - np.exp(-k * n * h)), rtol=0.01)
    np.testing.assert_allclose(sim.velocities()[:, [0, 2]], 0.0, atol=0.0)


@pytest.mark.parametrize("integrator, layout", [
    ("backward_euler", "particles"), ("projective", "particles"), ("projective", "grid"),
    ("vbd", "particles"), ("xpbd", "particles")])
def test_every_solver_takes_air_damping_per_mass(f64, integrator, layout):
    """Free particles of 0.01 and 1 kg (projective: its CG path), or a free cloth grid
    falling as one body (projective: its multigrid path), with air_damping gamma: every
    particle's speed follows the solver's closed-form step, mass-independent:
    v1 = (v0 + h g) / (1 + h gamma) for backward Euler, projective dynamics and VBD (drag in
    the incremental potential and projective's constant matrix: one iteration solves the
    step), v1 = v0 + h (g - gamma v0)
    for XPBD (drag with the other forces at the start of the step); both tend to g / gamma."""
    gamma, h, n = 3.0, 1e-2, 60
    scene = (falling_particles([0.01, 1.0], air_damping=gamma) if layout == "particles"
             else falling_cloth(6, air_damping=gamma))
    # one iteration each: exact only where the drag is in the Hessian (backward Euler's
    # Newton step, VBD's vertex block: without Chebyshev acceleration, which overshoots)
    # and in projective's constant matrix, not only in the gradient
    options = {"backward_euler": {"newton_iterations": 1}, "projective": {"iterations": 1},
               "vbd": {"iterations": 1, "rho": 0.0}, "xpbd": {}}[integrator]
    sim = tcloth.Simulator(scene, integrator, dt=h, **options)
    v = fall_speeds(sim, n)
    factor = 1 - h * gamma if integrator == "xpbd" else 1 / (1 + h * gamma)
    expected = G / gamma * (1 - factor ** n)
    np.testing.assert_allclose(v, expected, rtol=1e-6)
    assert expected == pytest.approx(G / gamma, rel=0.2)     # most of the way there


def test_air_damping_is_checked_saved_and_set_live(f64, tmp_path):
    """A negative or non-finite air_damping is a SceneError naming it and the value,
    from the Scene and from the live setter; a checkpoint keeps it (its continuation is
    bit for bit); the viewer's control sets it; a change keeps the scene's air_drag."""
    for bad in (-1.0, float("nan"), float("inf")):
        with pytest.raises(tcloth.SceneError, match=f"air_damping.*{bad}"):
            tcloth.Scene(air_damping=bad)
    sim = tcloth.Simulator(falling_particles([0.02, 0.5], air_drag=0.01, air_damping=1.5),
                           "symplectic_euler", dt=1e-3)
    with pytest.raises(tcloth.SceneError, match="air_damping.*-2"):
        sim.set_air_damping(-2.0)
    assert sim.scene.air_damping == 1.5
    sim.step(50)
    sim.save(str(tmp_path / "run.npz"))
    loaded = tcloth.Simulator.load(str(tmp_path / "run.npz"))
    assert (loaded.scene.air_drag, loaded.scene.air_damping) == (0.01, 1.5)
    sim.step(50)
    loaded.step(50)
    np.testing.assert_array_equal(loaded.velocities(), sim.velocities())
    controls = Controls(sim)
    assert controls.values["air_damping"] == 1.5
    controls.values["air_damping"] = 0.25
    controls.apply()
    assert (sim.scene.air_drag, sim.scene.air_damping) == (0.01, 0.25)
    v0 = sim.velocities()
    sim.step(1)
    k = 0.01 / np.array([0.02, 0.5]) + 0.25
    np.testing.assert_allclose(sim.velocities()[:, 1], v0[:, 1] + 1e-3 * (-G - k * v0[:, 1]),
                               rtol=1e-12)
