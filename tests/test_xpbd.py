"""XPBD: with many iterations a step lands near backward Euler's for springs, substeps
converge at first order, its spring projections conserve linear momentum exactly, and at
one step per frame on stiff cloth it is stable with pinned particles in place and a
hanging chain at its closed-form equilibrium."""
import numpy as np
import pytest

import tcloth
from conftest import hanging_chain
from tcloth.geometry.graph import colour_springs


def cloth(k, kd=0.0, n=8, pinned=None, gravity=(0.0, -9.81, 0.0)):
    scene = tcloth.Scene(gravity=gravity)
    scene.add_cloth(resolution=(n, n), size=(1, 1), mass=0.2, structural=(k, kd),
                    shear=(k / 10, kd / 2), flexion=(k / 100, kd / 10), pinned=pinned)
    return scene


def swinging(n, k=1e3):
    def scene():
        return cloth(k, n=n)
    warm = tcloth.Simulator(scene(), "backward_euler", dt=1 / 60)
    warm.step(20)
    return scene, warm.positions(), warm.velocities()


@pytest.mark.slow
def test_xpbd_converges_near_the_backward_euler_step(f64):
    """16 x 16 undamped cloth, one step of 1/60: the distance to backward Euler's step
    falls as iterations grow and levels off at XPBD's own fixed point, within 2 % of the
    step's motion (it drops the constraint Hessian's term, Macklin 2016 eq. 11)."""
    scene, x0, v0 = swinging(16)
    be = tcloth.Simulator(scene(), "backward_euler", dt=1 / 60, newton_tol=1e-13,
                          cg_tol=1e-13, newton_iterations=60)
    be.set_state(positions=x0, velocities=v0)
    be.step()
    moved = np.abs(be.positions() - x0).max()
    # the steps from Python, whose iteration count is read each step (a batch's is
    # compiled in: tests/test_batch.py)
    xpbd = tcloth.Simulator(scene(), "xpbd", dt=1 / 60, substeps=1, batch=False)
    gaps = []
    for iterations in (1, 10, 100, 1000):
        xpbd.set_integrator_options(iterations=iterations)
        xpbd.set_state(positions=x0, velocities=v0)
        xpbd.step()
        gaps.append(np.abs(xpbd.positions() - be.positions()).max())
    assert gaps[0] > gaps[1] > gaps[2]
    assert gaps[3] < 0.02 * moved, (gaps, moved)


@pytest.mark.slow
def test_xpbd_substeps_converge_at_first_order(f64):
    """One iteration per substep (Small Steps): 0.05 s of a swinging 8 x 8 cloth against
    RK4 at 1e-5 s: the order falls to 1, the error halving with the substep at 5e-5 s
    (coarser, it falls faster: orders 1.7-2.0 from 1.6e-3 s to 4e-4 s)."""
    scene, x0, v0 = swinging(8)
    ref = tcloth.Simulator(scene(), "rk4", dt=1e-5)
    ref.set_state(positions=x0, velocities=v0)
    ref.step(5000)
    errors = []
    for substeps in (256, 512, 1024):
        sim = tcloth.Simulator(scene(), "xpbd", dt=0.05, substeps=substeps, iterations=1)
        sim.set_state(positions=x0, velocities=v0)
        sim.step()
        errors.append(np.abs(sim.positions() - ref.positions()).max())
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    # the observed order falls toward 1 as the substep shrinks (1.3, then 0.96)
    assert orders[0] > orders[1] and abs(orders[1] - 1.0) < 0.15, (errors, orders)


def test_xpbd_conserves_the_momentum_of_a_free_cloth(f64):
    """Each spring's correction moves equal and opposite momenta (w_i m_i = 1): a free
    cloth with random velocities keeps its momentum to rounding, at any iteration count."""
    scene = cloth(1e3, kd=0.5, n=8, pinned=[], gravity=(0.0, 0.0, 0.0))
    v = np.random.default_rng(3).normal(size=(64, 3))
    m = scene.masses[:, None]
    sim = tcloth.Simulator(scene, "xpbd", dt=1 / 60, iterations=3)
    sim.set_state(velocities=v)
    sim.step(10)
    drift = np.abs((m * sim.velocities()).sum(0) - (m * v).sum(0)).max()
    assert drift < 1e-12 * (m * np.abs(v)).sum()


@pytest.mark.slow
@pytest.mark.parametrize("k", [1e4, 1e6])
def test_xpbd_is_stable_on_stiff_cloth_at_one_step_per_frame(f64, k):
    """The stiff cloth (k_s up to 1e6, damped, pinned at two corners) at dt = 1/60 for a
    simulated second: no blow-up, strain bounded, the pinned corners never move. Ten
    iterations do not satisfy such springs: the strain they leave holds spring energy
    above the start (k = 1e6: 786 J at its peak from 2 J), which the energy budget sees
    (InstabilityError, its hint naming the substeps that follow the stress wave); with
    those substeps the run stays within the budget, and leaves less."""
    n = 12
    peaks = []
    for iterations, substeps in ((10, 1), (10, "auto")):
        sim = tcloth.Simulator(cloth(k, kd=1.0, n=n, pinned=[(0, 0), (n - 1, 0)]), "xpbd",
                               dt=1 / 60, iterations=iterations, substeps=substeps,
                               energy_bound=substeps == "auto")
        corners = sim.positions()[sim.scene.pinned]
        energy = []
        for _ in range(60):
            sim.step()
            energy.append(sim.energy()["total"])
        assert sim.max_strain() < 0.06
        assert np.array_equal(sim.positions()[sim.scene.pinned], corners)
        peaks.append(max(energy))
    assert peaks[1] < peaks[0]
    budgeted = tcloth.Simulator(cloth(k, kd=1.0, n=n, pinned=[(0, 0), (n - 1, 0)]), "xpbd",
                                dt=1 / 60, iterations=10, substeps=1, split=False)
    with pytest.raises(tcloth.InstabilityError, match="more energy than the scene can supply"
                       ".*substeps='auto'"):
        budgeted.step(60)


def test_xpbd_reaches_the_hanging_chain_closed_form(f64):
    """Each spring of a hanging chain (conftest.hanging_chain) stretched by the weight
    below it over k."""
    scene, expected, stretch = hanging_chain()
    sim = tcloth.Simulator(scene, "xpbd", dt=1 / 60, iterations=200)
    sim.step(600)
    assert np.abs(sim.positions()[:, 1] - expected).max() < 0.02 * stretch


def test_spring_colouring_separates_springs_at_a_particle():
    tcloth.init()
    pairs = cloth(1e3, n=10).springs["pairs"]
    colours = colour_springs(pairs, 100)
    for c in range(colours.max() + 1):
        ends = pairs[colours == c].ravel()
        assert len(ends) == len(np.unique(ends))


def test_xpbd_options_are_checked():
    tcloth.init()
    for bad in ({"iterations": 0}, {"substeps": 1.5}):
        with pytest.raises(tcloth.SceneError, match=next(iter(bad))):
            tcloth.Simulator(cloth(1e3, n=4), "xpbd", dt=1 / 60, **bad)
