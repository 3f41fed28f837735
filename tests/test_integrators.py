"""Explicit integrators against closed forms, conservation laws and convergence order."""
import numpy as np
import pytest

import tcloth
from conftest import random_network, use_runtime

EXPLICIT = ["forward_euler", "symplectic_euler", "verlet", "rk4"]


def oscillator(k=40.0, m=0.5, stretch=0.1, kd=0.0, rest=1.0):
    """Particle 1 on a spring to pinned particle 0, displaced by ``stretch`` along x."""
    scene = tcloth.Scene(gravity=(0, 0, 0))
    scene.add_particles([[0, 0, 0], [rest + stretch, 0, 0]], mass=m, pinned=np.array([True, False]))
    scene.add_springs([[0, 1]], stiffness=k, damping=kd, rest_length=rest)
    return scene


def displacement_history(sim, steps, rest=1.0):
    out = np.empty(steps + 1)
    out[0] = sim.positions()[1, 0] - rest
    for s in range(steps):
        sim.step()
        out[s + 1] = sim.positions()[1, 0] - rest
    return out


@pytest.mark.parametrize("integrator", ["symplectic_euler", "verlet", "rk4"])
def test_oscillator_period(f64, integrator):
    k, m = 40.0, 0.5
    period = 2 * np.pi * np.sqrt(m / k)
    dt = period / 400
    sim = tcloth.Simulator(oscillator(k, m), integrator, dt=dt)
    u = displacement_history(sim, 2400)
    t = np.arange(len(u)) * dt
    crossings = [t[i] - u[i] * dt / (u[i + 1] - u[i]) for i in range(len(u) - 1)
                 if u[i] > 0 >= u[i + 1]]
    measured = np.mean(np.diff(crossings))
    assert abs(measured / period - 1) < 5e-3


def test_damped_oscillator_decays_at_analytic_rate(f64):
    k, m, kd, a = 40.0, 0.5, 0.6, 0.1
    gamma = kd / (2 * m)
    wd = np.sqrt(k / m - gamma ** 2)
    dt = 1e-3
    sim = tcloth.Simulator(oscillator(k, m, stretch=a, kd=kd), "rk4", dt=dt)
    u = displacement_history(sim, 3000)
    t = np.arange(len(u)) * dt
    exact = a * np.exp(-gamma * t) * (np.cos(wd * t) + gamma / wd * np.sin(wd * t))
    assert np.abs(u - exact).max() < 1e-6 * a
    peaks = [i for i in range(1, len(u) - 1) if u[i - 1] < u[i] >= u[i + 1]]
    rate = -np.polyfit(t[peaks], np.log(u[peaks]), 1)[0]
    assert abs(rate / gamma - 1) < 1e-3


@pytest.mark.parametrize("kd", [0.0, 2.0])
@pytest.mark.parametrize("integrator", EXPLICIT)
def test_linear_momentum_conserved(f64, integrator, kd):
    sim = tcloth.Simulator(random_network(n=8, seed=7, kd=kd), integrator, dt=1e-3)
    p0, _ = sim.momentum()
    sim.step(300)
    p1, _ = sim.momentum()
    scale = np.abs(sim.velocities()).max() * sim.scene.masses.sum()
    assert np.abs(p1 - p0).max() < 1e-12 * scale


@pytest.mark.parametrize("kd", [0.0, 2.0])
def test_symplectic_euler_conserves_angular_momentum(f64, kd):
    sim = tcloth.Simulator(random_network(n=8, seed=8, kd=kd), "symplectic_euler", dt=1e-3)
    _, l0 = sim.momentum()
    sim.step(300)
    _, l1 = sim.momentum()
    assert np.abs(l1 - l0).max() < 1e-11 * np.abs(l0).max()


def test_forward_euler_angular_momentum_drift_per_step_scales_as_dt_squared(f64):
    drifts = []
    for dt in (2e-4, 1e-4, 5e-5):
        sim = tcloth.Simulator(random_network(n=6, seed=9, kd=1.0), "forward_euler", dt=dt)
        _, l0 = sim.momentum()
        # closed form of one step's drift: L1 - L0 = dt^2 sum_i v_i x f_i
        expected = dt ** 2 * np.cross(sim.velocities(), sim.forces()).sum(0)
        sim.step(1)
        _, l1 = sim.momentum()
        assert np.allclose(l1 - l0, expected, rtol=1e-6, atol=1e-15)
        drifts.append(np.linalg.norm(l1 - l0))
    ratios = np.array(drifts[:-1]) / np.array(drifts[1:])
    assert np.allclose(ratios, 4.0, rtol=0.02)
    assert drifts[0] > 1e-12


def test_symplectic_euler_energy_bounded_over_1e5_steps(f64):
    scene = random_network(n=5, seed=10, k=(20.0, 60.0))
    sim = tcloth.Simulator(scene, "symplectic_euler", dt=2e-3)
    e0 = sim.energy()["total"]
    worst = 0.0
    for _ in range(100):
        sim.step(1000)
        worst = max(worst, abs(sim.energy()["total"] - e0))
    assert sim.num_steps == 100_000
    assert worst < 0.02 * abs(e0)


@pytest.mark.parametrize("dt_factor", [0.3, 0.03, 0.003])
def test_forward_euler_gains_energy_at_every_dt_without_damping(f64, dt_factor):
    k, m = 40.0, 0.5
    # energy_bound=False: the growth is the point here, not an instability to stop at
    sim = tcloth.Simulator(oscillator(k, m), "forward_euler", dt=dt_factor / np.sqrt(k / m),
                           energy_bound=False)
    e = [sim.energy()["total"]]
    for _ in range(50):
        sim.step()
        e.append(sim.energy()["total"])
    assert np.all(np.diff(e) > 0)
    # the linear oscillator's exact factor per forward Euler step: 1 + (omega dt)^2
    assert np.allclose(np.array(e[1:]) / e[:-1], 1 + dt_factor ** 2, rtol=1e-9)


T_END = 0.4


@pytest.fixture(scope="module")
def converged():
    """An undamped nonlinear network and its end state by RK4 at a tiny dt (reference)."""
    use_runtime("f64", __name__)
    scene = random_network(n=5, seed=11, k=(20.0, 60.0))
    ref = tcloth.Simulator(scene, "rk4", dt=T_END / 3200)
    ref.step(3200)
    return scene, ref.positions()


@pytest.mark.slow_cases("forward_euler-1", "rk4-4")
@pytest.mark.parametrize("integrator,order", [("forward_euler", 1), ("symplectic_euler", 1),
                                              ("verlet", 2), ("rk4", 4)])
def test_convergence_order(f64, converged, integrator, order):
    scene, x_ref = converged
    t_end = T_END
    errors = []
    for steps in (100, 200, 400):
        sim = tcloth.Simulator(scene, integrator, dt=t_end / steps)
        sim.step(steps)
        errors.append(np.abs(sim.positions() - x_ref).max())
    measured = np.log2(np.array(errors[:-1]) / errors[1:])
    assert np.allclose(measured, order, atol=0.15), measured
