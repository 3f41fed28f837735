"""Steps that split instead of failing (``tcloth/sim/split.py``), the strain bound's
weight rule (``tcloth/sim/instability.py``) and kernels that compile once."""
import numpy as np
import pytest

import tcloth
from tcloth.sim.split import RELAX
from test_frame_rate_honesty import landing


def oscillator(k=400.0, m=0.01):
    """A particle on a spring to a pinned one, no gravity, moving: omega = sqrt(k / m) =
    200 / s."""
    scene = tcloth.Scene(gravity=(0.0, 0.0, 0.0))
    scene.add_particles([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]], mass=m,
                        velocities=[[0.0, 0.0, 0.0], [0.5, 0.0, 0.0]], pinned=[True, False])
    scene.add_springs([[0, 1]], stiffness=k)
    return scene


def test_a_failing_step_splits_into_the_same_simulation_at_a_finer_step(f64):
    """Forward Euler gains energy on an undamped spring at every step (by 1 + (omega dt)^2,
    4 % here) until a step leaves more than the budget allows. Split, that step is two
    steps of dt / 2 from the same start, which gain less and pass: bit for bit what a
    simulator that takes the steps before at dt and that one at dt / 2 (``set_dt``)
    computes, in a batch (the default) as step by step. The split stays for RELAX steps
    that pass, then the whole step is tried again."""
    dt = 1e-3
    split = tcloth.Simulator(oscillator(), "forward_euler", dt=dt)
    with pytest.raises(tcloth.InstabilityError) as err:
        tcloth.Simulator(oscillator(), "forward_euler", dt=dt, split=False).step(10000)
    bad = err.value.step
    assert bad > 20
    split.step(bad)
    stats = split.step_stats()
    assert stats == {"split_steps": 1, "pieces": 2, "retries": 1, "finest": 2,
                     "pieces_now": 2}
    reference = tcloth.Simulator(oscillator(), "forward_euler", dt=dt, split=False,
                                 batch=False)
    reference.step(bad - 1)
    reference.set_dt(dt / 2)
    reference.step(2)
    assert np.array_equal(split.positions(), reference.positions())
    assert np.array_equal(split.velocities(), reference.velocities())
    assert split.num_steps == bad and split.time == pytest.approx(bad * dt, rel=1e-12)
    split.set_state(velocities=0.01 * split.velocities())     # far inside the budget
    split.step(RELAX - 1)
    assert split.step_stats()["split_steps"] == RELAX
    assert split.step_stats()["pieces_now"] == 1


def test_past_the_finest_split_the_step_raises_and_keeps_its_start(f64):
    """Pinned particles pulled apart at 1 m/s stretch their spring past the strain bound at
    step 11 whatever the step's length: every split fails, and the error names the whole
    step and the splits tried, with the state of step 10 kept."""
    scene = tcloth.Scene(gravity=(0.0, 0.0, 0.0))
    scene.add_particles([[0.0, 0.0, 0.0], [0.105, 0.0, 0.0]], mass=1.0,
                        velocities=[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], pinned=True)
    scene.add_springs([[0, 1]], stiffness=100.0)
    sim = tcloth.Simulator(scene, "backward_euler", dt=0.01, split=8)
    with pytest.raises(tcloth.InstabilityError, match=r"step 11 .*Split into 2 to 8 steps"):
        sim.step(20)
    assert sim.num_steps == 10 and sim.positions()[1, 0] == pytest.approx(0.205, abs=1e-12)
    assert sim.step_stats()["retries"] == 4 and sim.step_stats()["pieces_now"] == 1
    with pytest.raises(tcloth.SceneError, match="split"):
        tcloth.Simulator(scene, split=0)


@pytest.mark.slow
def test_xpbd_at_one_substep_lands_a_cloth_by_splitting_the_landing(f64):
    """XPBD at one substep of ten iterations cannot stop a cloth landing at 1/60: its
    springs take more energy than the fall gave, and without splits the landing's step
    raises. With the split on (the default) the landing's steps split, the cloth lands
    within 50 % strain at every step (NumPy) and its free fall before took whole steps."""
    scene = landing(12)
    with pytest.raises(tcloth.InstabilityError):
        tcloth.Simulator(scene, "xpbd", dt=1 / 60, substeps=1, split=False).step(30)
    sim = tcloth.Simulator(scene, "xpbd", dt=1 / 60, substeps=1)
    pairs, rest = scene.springs["pairs"], scene.springs["rest_length"]
    for step in range(30):
        sim.step()
        x = sim.positions()
        strain = np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1) / rest - 1.0
        assert strain.max() < 0.5, step
        if step == 5:
            assert sim.step_stats()["split_steps"] == 0
    assert sim.step_stats()["split_steps"] > 0


@pytest.mark.slow
def test_a_spring_holding_no_more_than_the_weight_may_pass_the_strain_bound(f64):
    """A 10 g particle hanging from a pinned one on a spring of 0.05 m and 1 N/m stretches
    by m g / k = 9.8 cm, strain 1.96 at rest (closed form): its tension never exceeds
    twice the weight, so the strain bound does not stop it. A spring of 10 N/m between
    two pinned particles pulled apart at 1.05 m/s, beside a falling particle of mass M,
    passes strain 1 at step 5 (strain 1.05, tension 0.525 N): a torn spring for M = 10 g
    (twice its weight is 0.196 N); for M = 100 g (1.962 N) not until its tension passes
    that, at step 19 (strain 3.99, 1.995 N; step 18: 1.89 N)."""
    m, k, l0, g = 0.01, 1.0, 0.05, 9.81
    scene = tcloth.Scene(gravity=(0.0, -g, 0.0), air_drag=0.02)
    scene.add_particles([[0.0, 0.0, 0.0], [0.0, -l0, 0.0]], mass=m, pinned=[True, False])
    scene.add_springs([[0, 1]], stiffness=k, damping=0.02)
    sim = tcloth.Simulator(scene, "backward_euler", dt=0.01)
    sim.step(1500)
    assert sim.max_strain() == pytest.approx(m * g / (k * l0), rel=1e-3)
    for free_mass, step, strain in ((0.01, 5, r"1\.05"), (0.1, 19, r"3\.99")):
        pulled = tcloth.Scene(gravity=(0.0, -g, 0.0))
        pulled.add_particles([[0.0, 0.0, 0.0], [0.0, -l0, 0.0]], mass=m,
                             velocities=[[0.0, 0.0, 0.0], [0.0, -1.05, 0.0]], pinned=True)
        pulled.add_particles([[1.0, 0.0, 0.0]], mass=free_mass)
        pulled.add_springs([[0, 1]], stiffness=10.0)
        sim = tcloth.Simulator(pulled, "backward_euler", dt=0.01, split=False)
        with pytest.raises(tcloth.InstabilityError, match=rf"step {step} .*strain {strain}"):
            sim.step(30)


@pytest.mark.parametrize("integrator", ["symplectic_euler", "projective", "vbd", "xpbd"])
def test_no_kernel_compiles_after_the_first_step(f64, integrator):
    """The step's kernels take the simulator's two States in one order: the end of a step
    is copied into the first, not swapped with it, so a second step (and a split one, with
    its own dt) compiles nothing new."""
    sim = tcloth.Simulator(landing(8), integrator, dt=1 / 60 if integrator in
                           ("projective", "vbd", "xpbd") else 1e-4)
    sim.step()
    sim.positions()
    before = tcloth.runtime.compilations()
    sim.step(3)
    sim.positions()
    assert tcloth.runtime.compilations() == before
