"""Vertex Block Descent: it converges to the backward Euler step it descends on, each
vertex's gradient and Hessian block match finite differences of the incremental
potential, and at one step per frame on stiff cloth it is stable, dissipative, keeps a
free cloth's momentum and pinned particles in place, and reaches a hanging chain's
closed-form equilibrium."""
import numpy as np
import pytest
import taichi as ti

import tcloth
from conftest import hanging_chain
from tcloth.geometry.graph import colour_graph
from tcloth.contact.topology import contact_topology


def cloth(k, kd=1.0, n=8, pinned=None, gravity=(0.0, -9.81, 0.0)):
    scene = tcloth.Scene(gravity=gravity)
    scene.add_cloth(resolution=(n, n), size=(1, 1), mass=0.2, structural=(k, kd),
                    shear=(k / 10, kd / 2), flexion=(k / 100, kd / 10), pinned=pinned)
    return scene


def swinging(n, k=1e3, kd=0.5):
    """A hanging cloth 20 backward Euler steps after release from flat: (scene factory,
    positions, velocities)."""
    def scene():
        return cloth(k, kd=kd, n=n)
    warm = tcloth.Simulator(scene(), "backward_euler", dt=1 / 60)
    warm.step(20)
    return scene, warm.positions(), warm.velocities()


@pytest.mark.slow
def test_vbd_converges_to_the_backward_euler_step(f64):
    """16 x 16 cloth, dt = 1/60: the distance to the tightly solved backward Euler step
    falls as the iterations grow (plain block descent, and Chebyshev from 16), and is
    below 1e-6 of the cloth's size at convergence (Chebyshev 0.95: 5e-9 m after 1,024;
    plain descent needs 4,096 for 3e-10 m, docs/realtime.md)."""
    scene, x0, v0 = swinging(16)
    be = tcloth.Simulator(scene(), "backward_euler", dt=1 / 60, newton_tol=1e-13,
                          cg_tol=1e-13, newton_iterations=60)
    be.set_state(positions=x0, velocities=v0)
    be.step()
    target = be.positions()
    for rho, counts in ((0.0, (1, 4, 16, 64, 256)), (0.95, (16, 64, 256, 1024))):
        vbd = tcloth.Simulator(scene(), "vbd", dt=1 / 60, rho=rho, initial_guess="inertia",
                               substeps=1, batch=False)   # the iterations change between steps
        gaps = []
        for iterations in counts:
            vbd.set_integrator_options(iterations=iterations)
            vbd.set_state(positions=x0, velocities=v0)
            vbd.step()
            gaps.append(np.abs(vbd.positions() - target).max())
        assert all(b < a for a, b in zip(gaps, gaps[1:])), (rho, gaps)
    assert gaps[-1] < 1e-6, gaps
    # the pinned corners moved with their velocity, as in backward Euler
    assert np.array_equal(vbd.positions()[scene().pinned], x0[scene().pinned])


@pytest.mark.slow
@pytest.mark.parametrize("friction", [0.0, 0.3])
def test_each_vertex_gradient_and_block_match_finite_differences(f64, friction):
    """g_i and H_i of VBD's local Newton step against central differences of backward
    Euler's incremental potential E (springs with damping, gravity, drag, a sphere's
    penalty and friction), for vertices in the middle, at an edge and at a corner
    touching the sphere, of a swinging cloth. With friction, the gradient only: the
    friction's block is its majorant's (``colliders.add_dissipation``), not its
    potential's exact Hessian."""
    def scene():
        s = cloth(1e3, kd=0.5, n=6)
        s.air_drag = 0.02
        # the swinging cloth's lowest corner (particle 35) within its contact offset
        s.add_sphere(center=(0.5, 0.3, 0.25), radius=0.15, friction=friction,
                     thickness=0.02)
        return s
    warm = tcloth.Simulator(scene(), "backward_euler", dt=1 / 60)
    warm.step(25)
    x0, v0 = warm.positions(), warm.velocities()
    sim = tcloth.Simulator(scene(), "vbd", dt=1 / 60)
    sim.set_state(positions=x0, velocities=v0)
    vbd, h = sim.integrator, 1 / 60
    x = sim.state.x
    vbd.potential.begin(sim.state.x, sim.state.v, h, 0.0, vbd.prev)
    rng = np.random.default_rng(1)
    xt = x0 + h * v0 + 1e-3 * rng.normal(size=x0.shape)

    def energy(y):
        x.from_numpy(y)
        return vbd.potential.evaluate(x, h, h, False)[0]

    def local(y, p):
        x.from_numpy(y)
        return vbd.local_system(x, h, h, p)
    eps = 1e-6
    for p in (14, 3, 35):
        g, block = local(xt, p)
        fd_g, fd_h = np.zeros(3), np.zeros((3, 3))
        for c in range(3):
            up, down = xt.copy(), xt.copy()
            up[p, c] += eps
            down[p, c] -= eps
            fd_g[c] = (energy(up) - energy(down)) / (2 * eps)
            fd_h[:, c] = (local(up, p)[0] - local(down, p)[0]) / (2 * eps)
        assert np.abs(g - fd_g).max() < 1e-6 * (np.abs(g).max() + 1.0), (p, g, fd_g)
        if friction == 0.0:
            # H_i is the exact block plus, for each compressed spring at p, its negative
            # transverse stiffness clamped to 0: k (l0 / l - 1) (I - n n^T); at the
            # sphere, along its normal n only (the penalty's block leaves out the
            # surface's curvature term k phi (I - n n^T) / r, negative inside)
            error = block - fd_h - projection(scene(), xt, p)
            if p == 35:
                n = (xt[p] - (0.5, 0.3, 0.25)) / np.linalg.norm(xt[p] - (0.5, 0.3, 0.25))
                error = n @ error @ n
            assert np.abs(error).max() < 1e-5 * np.abs(fd_h).max(), (p, block, fd_h)


def layers():
    """A 6 x 6 cloth with a 4 x 4 one 4 mm above it, inside the 6 mm self-contact."""
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0))
    for y, n in ((0.0, 6), (0.004, 4)):
        scene.add_cloth(resolution=(n, n), size=(0.3, 0.3), center=(0.01 * n, y, 0.0),
                        mass=0.02, structural=(400.0, 0.05), shear=(80.0, 0.02),
                        flexion=(10.0, 0.005))
    scene.set_self_collision(thickness=0.006)
    return scene


def test_each_vertex_self_contact_is_evaluated_afresh_and_matches_finite_differences(f64):
    """Self-contact in VBD's sweeps (``SelfContact.vertex_system``): each particle's
    rows of the contact list are indexed once a step (every row at each of its four
    particles, once), and a particle's gradient, its rows evaluated at the current
    positions, matches central differences of the contact's part of the incremental
    potential (the penalty, and the normal damping lagged at the step's start) for every
    particle in a row, on two layers pressed into each other."""
    scene = layers()
    sim = tcloth.Simulator(scene, "vbd", dt=1 / 60)
    vbd, h = sim.integrator, 1 / 60
    rng = np.random.default_rng(3)
    x0 = scene.positions + 5e-4 * rng.normal(size=scene.positions.shape)
    sim.set_state(positions=x0, velocities=rng.normal(scale=0.05, size=x0.shape))
    x, start_x = sim.state.x, vbd.potential.x0
    vbd.potential.begin(sim.state.x, sim.state.v, h, 0.0, vbd.prev)
    term = vbd.vertex_terms[0]
    cl, rows = sim.contact.candidates, sim.contact.count
    ids = cl.ids.to_numpy()[:rows]
    start, entries = term.rows.start.to_numpy(), term.rows.entries.to_numpy()
    for p in range(len(x0)):
        listed = sorted(map(tuple, entries[start[p]:start[p + 1]]))
        assert listed == sorted(zip(*np.nonzero(ids == p))), p
    acc, grad = ti.field(ti.f64, shape=2), ti.Vector.field(3, ti.f64, shape=len(x0))

    @ti.kernel
    def gradient(p: ti.i32) -> ti.types.vector(3, ti.f64):
        return term.vertex_system(p, x, start_x, h)[0]

    def energy(y):
        x.from_numpy(y)
        acc.fill(0.0)
        term.add_incremental(x, start_x, h, False, acc, grad)
        return acc[0]
    xt = x0 + h * sim.velocities() + 5e-4 * rng.normal(size=x0.shape)
    eps, touching = 1e-7, 0
    for p in np.unique(ids):
        x.from_numpy(xt)
        g = np.array(gradient(p))
        fd = np.zeros(3)
        for c in range(3):
            up, down = xt.copy(), xt.copy()
            up[p, c] += eps
            down[p, c] -= eps
            fd[c] = (energy(up) - energy(down)) / (2 * eps)
        assert np.abs(g - fd).max() < 1e-6 * (np.abs(fd).max() + 1e-3), (p, g, fd)
        touching += np.abs(fd).max() > 1e-2
    assert touching >= 10


@pytest.mark.slow
def test_vbd_reads_the_contact_list_the_stage_made_again_larger(f64):
    """The stage replaces its candidate list with a larger one where a search outgrew
    it; VBD's sweeps, compiled for the first list, compile again for the new one (the
    term's ``layout``) and step exactly as a simulator that never had the smaller list."""
    grown, fresh = (tcloth.Simulator(layers(), "vbd", dt=1 / 60, substeps=1)
                    for _ in range(2))
    grown.step(1)
    broad = grown.contact.broad
    term = grown.integrator.vertex_terms[0]
    before = term.layout()
    broad.candidates = broad._list(2 * broad.candidates.capacity)
    x, v = grown.positions(), grown.velocities()
    grown.set_state(positions=x, velocities=v)
    fresh.set_state(positions=x, velocities=v)
    grown.step(2)
    fresh.step(2)
    assert term.layout() > before
    assert grown.contact.candidates is broad.candidates
    assert np.array_equal(grown.positions(), fresh.positions())
    assert np.abs(grown.positions() - x).max() > 1e-3


def projection(scene, x, p):
    """What projecting the compressed springs at particle p adds to its block (NumPy)."""
    sp = scene.springs
    out = np.zeros((3, 3))
    for (i, j), k, l0 in zip(sp["pairs"], sp["stiffness"], sp["rest_length"]):
        if p in (i, j):
            d = x[i] - x[j]
            length = np.linalg.norm(d)
            n = d / length
            if length < l0:
                out += k * (l0 / length - 1.0) * (np.eye(3) - np.outer(n, n))
    return out


@pytest.mark.slow
@pytest.mark.parametrize("k", [1e4, 1e6])
def test_vbd_is_stable_on_stiff_cloth_at_one_step_per_frame(f64, k):
    """The implicit tests' stiff cloth (k_s up to 1e6, pinned at two corners) at dt =
    1/60, one simulated second: no blow-up, strain below 6 %, the pinned corners never
    move.
    Unconverged, a step is not backward Euler's and can gain energy (the springs keep
    strain the solve did not remove): at 20 iterations the largest one-step rise is
    larger than at 100 (Chebyshev 0.95), where the energy after the second is below the
    start (docs/vbd.md has the table). The energy budget, which counts the springs'
    energy, sees the gain at 20 iterations on the stiffest cloth (InstabilityError with
    a hint at the substeps)."""
    n = 12
    pinned = [(0, 0), (n - 1, 0)]
    rises = []
    for iterations, rho in ((20, 0.9), (100, 0.95)):
        sim = tcloth.Simulator(cloth(k, n=n, pinned=pinned), "vbd", dt=1 / 60,
                               iterations=iterations, rho=rho, substeps=1,
                               energy_bound=False)
        corners = sim.positions()[sim.scene.pinned]
        energy = [sim.energy()["total"]]
        for _ in range(60):
            sim.step()
            energy.append(sim.energy()["total"])
        assert sim.max_strain() < 0.06
        assert np.array_equal(sim.positions()[sim.scene.pinned], corners)
        rises.append(np.diff(energy).max())
    assert rises[1] < rises[0]
    assert energy[-1] < energy[0]
    if k == 1e6:
        budgeted = tcloth.Simulator(cloth(k, n=n, pinned=pinned), "vbd", dt=1 / 60,
                                    iterations=20, substeps=1, split=False)
        with pytest.raises(tcloth.InstabilityError, match="substeps='auto'"):
            budgeted.step(60)


def test_vbd_keeps_the_momentum_of_a_free_cloth_as_it_converges(f64):
    """No gravity, no pins, a random velocity field: the springs' forces are equal and
    opposite, so backward Euler's step conserves linear momentum. A vertex update
    balances its own springs only, so VBD does as it converges: the drift of one step
    falls with the iterations to rounding."""
    scene = cloth(1e3, kd=0.5, n=8, pinned=[], gravity=(0.0, 0.0, 0.0))
    rng = np.random.default_rng(3)
    v = rng.normal(size=(64, 3))
    m = scene.masses[:, None]
    p0, scale = (m * v).sum(0), (m * np.abs(v)).sum()
    drift = []
    sim = tcloth.Simulator(scene, "vbd", dt=1 / 60, rho=0.95, substeps=1, batch=False)
    for iterations in (10, 100, 1000):
        sim.set_integrator_options(iterations=iterations)
        sim.set_state(velocities=v)
        sim.step()
        drift.append(np.abs((m * sim.velocities()).sum(0) - p0).max() / scale)
    assert drift[0] > drift[1] > drift[2]
    assert drift[2] < 1e-12


@pytest.mark.slow
def test_a_cloth_on_a_frictionless_floor_keeps_its_momentum(f32):
    """Nothing pushes along a frictionless floor, so a cloth lying on it at rest stays at
    rest and one sliding over it keeps its speed, with VBD's defaults (Chebyshev's mix
    on) at one step per frame. The mix used to extrapolate the particles the floor's
    penalty holds, and the resting cloth crept 6 cm/s sideways within 0.5 s (0.018 kg
    m/s, particles at up to 0.38 m/s); the sliding one raised InstabilityError at its
    second step."""
    for n, size, mass, speed in ((24, 1.2, 0.3, 0.0), (8, 0.3, 0.02, 1.0)):
        scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0))
        scene.add_cloth(resolution=(n, n), size=(size, size), center=(0.0, 0.006, 0.0),
                        mass=mass, structural=(400.0, 0.05), shear=(80.0, 0.02),
                        flexion=(10.0, 0.005), pinned=[])
        scene.add_plane((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), friction=0.0)
        sim = tcloth.Simulator(scene, "vbd", dt=1.0 / 60.0)
        v = np.zeros((scene.num_particles, 3))
        v[:, 0] = speed
        sim.set_state(velocities=v)
        sim.step(30)
        p = sim.momentum()[0]
        assert abs(p[0] - mass * speed) < 1e-4 and abs(p[2]) < 2e-4, (n, p)
        drift = sim.velocities()[:, [0, 2]] - [speed, 0.0]
        assert np.abs(drift).max() < 0.01, (n, np.abs(drift).max())


def on_floor(friction, height):
    """A 4 x 4 cloth of 0.2 m and 0.02 kg lying flat at ``height`` above a floor (its
    contact 5 mm thick, 1,000 N/m) of friction ``friction``."""
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0))
    scene.add_cloth(resolution=(4, 4), size=(0.2, 0.2), center=(0.0, height, 0.0), mass=0.02,
                    structural=(400.0, 0.05), shear=(80.0, 0.02), flexion=(10.0, 0.005),
                    pinned=[])
    scene.add_plane((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), friction=friction)
    return scene


def test_friction_only_slows_a_cloth_pressed_into_a_floor(f32):
    """Coulomb friction opposes sliding and at most stops it: a cloth sliding at 0.5 m/s
    with its particles 4 mm inside the floor's contact (a normal force of 4 N each, over
    300 times their weight, as where a falling cloth lands) keeps a velocity along its
    sliding between 0 and 0.5 m/s and none across it, with VBD's defaults at one step
    per frame. Friction's potential is a cone in the sliding velocity, flat along it:
    a vertex's Newton step with the cone's own Hessian block, inertia alone against the
    friction along the sliding, overshot the stop (particles at -0.18 and 0.70 m/s after
    the first step; the fold's landing row shot off at up to 15 m/s)."""
    scene = on_floor(0.6, 0.001)
    sim = tcloth.Simulator(scene, "vbd", dt=1.0 / 60.0)
    v = np.zeros((scene.num_particles, 3))
    v[:, 0] = 0.5
    sim.set_state(velocities=v)
    for _ in range(3):
        sim.step()
        v = sim.velocities()
        assert v[:, 0].min() > -1e-3 and v[:, 0].max() < 0.5 + 1e-3, v[:, 0]
        assert np.abs(v[:, 2]).max() < 1e-3, v[:, 2]


def test_a_step_in_substeps_is_the_substeps_as_steps(f64):
    """A step of dt in two substeps is two steps of dt / 2: a cloth sliding at 0.5 m/s
    onto a floor of friction 0.6 from 1 mm above its contact, with VBD's iterations and
    Chebyshev's mix at their defaults and the inertial guess (the adaptive one reads the
    force the simulator's steps leave). The second substep used to read its start from
    the State it writes, which by then held the inertial prediction x0 + h v0: its
    friction pressed with the normal force of that deeper point and its contact planes
    were placed there (the ends 3.7 mm apart)."""
    scene = on_floor(0.6, 0.006)
    sim = tcloth.Simulator(scene, "vbd", dt=1.0 / 60.0, initial_guess="inertia", substeps=2)
    v0 = np.zeros((scene.num_particles, 3))
    v0[:, 0], v0[:, 1] = 0.5, -0.3
    sim.set_state(velocities=v0)
    sim.step()
    x, v = sim.positions(), sim.velocities()
    sim.set_dt(1.0 / 120.0)
    sim.set_integrator_options(substeps=1)
    sim.set_state(positions=scene.positions, velocities=v0)
    sim.step(2)
    assert sim.contact_stats()["guard_corrections"] == 0
    assert np.abs(sim.positions() - x).max() < 1e-12, np.abs(sim.positions() - x).max()
    assert np.abs(sim.velocities() - v).max() < 1e-9, np.abs(sim.velocities() - v).max()


def test_vbd_reaches_the_hanging_chain_closed_form(f64):
    """A chain of masses hanging from a pinned end (conftest.hanging_chain): each spring
    stretched by the weight below it over k."""
    scene, expected, stretch = hanging_chain()
    sim = tcloth.Simulator(scene, "vbd", dt=1 / 60, iterations=30)
    sim.step(600)
    assert np.abs(sim.positions()[:, 1] - expected).max() < 0.02 * stretch
    assert np.abs(sim.positions()[:, [0, 2]]).max() < 1e-9


@pytest.mark.slow
def test_a_checkpoint_keeps_the_adaptive_guess(f64, tmp_path):
    """The adaptive guess reads the last step's net force from the state: a saved and
    loaded simulator continues bit for bit (the first step after a plain set_state takes
    the gravity guess instead, and lands elsewhere within the solve's error)."""
    path = str(tmp_path / "vbd.npz")
    sim = tcloth.Simulator(cloth(1e3, n=8), "vbd", dt=1 / 60)
    sim.step(10)
    sim.save(path)
    loaded = tcloth.Simulator.load(path)
    fresh = tcloth.Simulator(cloth(1e3, n=8), "vbd", dt=1 / 60)
    fresh.set_state(positions=sim.positions(), velocities=sim.velocities())
    for s in (sim, loaded, fresh):
        s.step(5)
    assert np.array_equal(sim.positions(), loaded.positions())
    assert not np.array_equal(sim.positions(), fresh.positions())


def test_colouring_separates_every_spring_and_counts_on_grids_and_meshes():
    """No spring joins two vertices of one colour; a grid cloth with the three spring
    families takes 7 colours in index order (docs/realtime.md lists the counts)."""
    scene = cloth(1e3, n=16)
    pairs = scene.springs["pairs"]
    n = scene.num_particles
    both = np.concatenate([pairs, pairs[:, ::-1]])
    both = both[np.argsort(both[:, 0], kind="stable")]
    start = np.searchsorted(both[:, 0], np.arange(n + 1))
    colours = colour_graph(start, both[:, 1], n)
    assert np.all(colours[pairs[:, 0]] != colours[pairs[:, 1]])
    assert colours.max() + 1 == 7
    # a triangle mesh's edges only (the topology's edge list)
    topo = contact_topology(scene)
    e = topo["edges"]
    mesh_colours = colour_graph(topo["start"], topo["neighbours"], n)
    assert np.all(mesh_colours[e[:, 0]] != mesh_colours[e[:, 1]])


def test_vbd_options_are_checked():
    tcloth.init()
    for bad, word in (({"iterations": 0}, "iterations"), ({"rho": 1.0}, "rho"),
                      ({"initial_guess": "zero"}, "initial_guess")):
        with pytest.raises(tcloth.SceneError, match=word):
            tcloth.Simulator(cloth(1e3, n=4), "vbd", dt=1 / 60, **bad)
