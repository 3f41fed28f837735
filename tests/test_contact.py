"""The contact stage's guarantee (tcloth/contact/): no cloth edge crosses a cloth triangle
between two steps and no particle ends a step inside or through a collider, whatever the
integrator and dt. Checked with NumPy alone: ``tcloth.testing.crossings`` (itself checked here
against a brute force), signed distances and slab tests of the particle paths
(tools/bench_contact.py, whose stress set these are small versions of), the thrown
cloths' layer order and their momentum."""
import functools
import os

import numpy as np
import pytest

import tcloth
from tcloth.contact import projection, stage as stage_module
from tcloth.viewer import contact_lines

from tcloth.testing import folding
from tcloth.testing.colliders import signed_distances
from tcloth.testing.contact_cases import (CLOTH, centre, falling, guard_step, order_kept,
                                          run_case, side, sliding, thrown)
from tcloth.testing.crossings import count_crossings, crossing_pairs, triangle_edges

HERE = os.path.dirname(os.path.abspath(__file__))


# -- the independent counter -----------------------------------------------------------------
def brute_force_crossings(x, triangles):
    """Every (edge, triangle) pair sharing no particle, tested by solving
    a + u (b - a) + w (c - a) = p + s (q - p) for (u, w, s)."""
    hits = set()
    edges = triangle_edges(triangles)
    for e, (i, j) in enumerate(edges):
        for t, tri in enumerate(triangles):
            if i in tri or j in tri:
                continue
            a, b, c = x[tri]
            m = np.column_stack([b - a, c - a, x[i] - x[j]])
            if abs(np.linalg.det(m)) < 1e-14:
                continue
            u, w, s = np.linalg.solve(m, x[i] - a)
            if u >= 0 and w >= 0 and u + w <= 1 and 0 < s < 1:
                hits.add((e, t))
    return hits


def test_crossing_counter_matches_a_brute_force():
    rng = np.random.default_rng(3)
    for _ in range(5):
        x = rng.uniform(-1.0, 1.0, size=(30, 3))
        triangles = np.array([rng.choice(30, 3, replace=False) for _ in range(25)])
        found = {tuple(p) for p in crossing_pairs(x, triangles)}
        assert found == brute_force_crossings(x, triangles)
        assert len(found) > 5
    # two flat cloths, one through the other: each crossing edge is counted once. The
    # second is moved along x by 5 cm: centred as the first, its edges met the first's
    # exactly on its grid lines, where the two counts' rounding decides (NumPy 2.4 counted
    # 19 and 22 there)
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(4, 4), size=(1.0, 1.0), plane="xz", **CLOTH)
    scene.add_cloth(resolution=(4, 4), size=(1.0, 1.0), plane="xy", center=(0.05, 1.0, 0.0),
                    **CLOTH)
    x, tri = scene.positions.astype(np.float64), scene.triangles
    assert count_crossings(x, tri) == len(brute_force_crossings(x, tri)) > 0


# -- the guard on one step's motion ----------------------------------------------------------
def flight(masses, res=12):
    """Two cloths 0.1 m apart thrown at each other at 20 m/s relative: one free-flight step
    of 1/60 s would take each wholly through the other (the layers swapped, no crossing
    at either end)."""
    scene, x, v, cloths = thrown(20.0, res=res, masses=masses)
    sim = tcloth.Simulator(scene, "symplectic_euler", dt=1.0 / 60.0)
    sim.set_state(positions=x, velocities=v)
    return sim, scene, x, v, cloths


@pytest.mark.slow
@pytest.mark.parametrize("jacobi", [False, True])
def test_guard_stops_cloths_passing_wholly_through_each_other(f64, monkeypatch, jacobi):
    """The projection (Gauss-Seidel as on CPUs, and Jacobi as on GPUs), and the fail-safe
    alone (no rounds of projection), each turn a step that would swap the layers of two
    cloths of unequal mass into one that keeps them apart: zero crossings, the order
    kept. The projection's corrections are equal and opposite: momentum conserved to
    rounding."""
    monkeypatch.setattr(projection, "JACOBI", jacobi)
    sim, scene, x, v, cloths = flight((0.05, 0.1))
    sides = (side(x, centre(cloths[0]), cloths[1]), side(x, centre(cloths[1]), cloths[0]))
    free = x + v / 60.0
    assert count_crossings(free, scene.triangles) == 0
    assert not order_kept(free, cloths, sides)           # free flight swaps them
    for rounds in (stage_module.ROUNDS, 0):
        monkeypatch.setattr(stage_module, "ROUNDS", rounds)
        before = sim.contact_stats()
        x1, v1 = guard_step(sim, x, v, 1.0 / 60.0)
        assert count_crossings(x1, scene.triangles) == 0
        assert order_kept(x1, cloths, sides)
        stats = {k: sim.contact_stats()[k] - before[k]
                 for k in ("guard_corrections", "failsafe_steps", "failsafe_vertices")}
        if rounds:
            assert stats["guard_corrections"] > 0 and stats["failsafe_steps"] == 0
            m = scene.masses[:, None]
            scale = float(np.sum(scene.masses)) * 10.0
            np.testing.assert_allclose((m * v1).sum(0), (m * v).sum(0), atol=1e-12 * scale)
        else:
            assert stats["failsafe_steps"] == 1 and stats["failsafe_vertices"] > 0


@pytest.mark.slow
@pytest.mark.parametrize("jacobi", [False, True])
def test_the_guard_adds_no_energy_at_any_dt(f64, monkeypatch, jacobi):
    """Two parallel cloths a tenth of the thickness apart closing at 1 m/s: the guard
    moves them to a quarter of the thickness apart. Turning that move into a velocity
    over dt took their kinetic energy from 0.019 J to 225 J at dt = 1e-5 s (2.4 J at
    1e-4, 0.042 J at 1e-3); the guard removes their approaching normal velocity instead.
    Kinetic energy never rises, momentum is kept, and the layers keep their order
    without crossing (NumPy); with the Gauss-Seidel projection and the Jacobi one."""
    monkeypatch.setattr(projection, "JACOBI", jacobi)
    scene, x, v, cloths = thrown(1.0, res=12, masses=(0.05, 0.1), gap=0.0006)
    sim = tcloth.Simulator(scene, "symplectic_euler", dt=1e-5)
    m = scene.masses[:, None]
    kinetic = lambda u: 0.5 * float(np.sum(m * u * u))
    sides = (side(x, centre(cloths[0]), cloths[1]), side(x, centre(cloths[1]), cloths[0]))
    for dt in (1e-5, 1e-4, 1e-3, 1.0 / 60.0, 1.0 / 30.0):
        x1, v1 = guard_step(sim, x, v, dt)
        assert kinetic(v1) <= kinetic(v) * (1.0 + 1e-9), dt
        np.testing.assert_allclose((m * v1).sum(0), (m * v).sum(0),
                                   atol=1e-12 * float(m.sum()))
        assert count_crossings(x1, scene.triangles) == 0 and order_kept(x1, cloths, sides)


def test_a_particle_that_started_inside_a_collider_is_not_pushed_round_its_edge(f64):
    """A particle 0.1 mm inside a box under its top face, 5 mm from a side face, that a
    step would take 1 cm deeper: pushed out along the nearest face's normal at its end,
    it left by the side face, a centimetre below where it was, dragging its cloth round
    the box's edge through the cloth lying there (the 64 x 64 fold's crossings). It stays
    where it was instead, its velocity into the box removed."""
    scene = tcloth.Scene(gravity=(0.0, 0.0, 0.0))
    scene.add_particles([[0.0, 0.0999, 0.095]])
    scene.add_box((0.0, 0.0, 0.0), (0.1, 0.1, 0.1))
    sim = tcloth.Simulator(scene, dt=1.0 / 60.0)
    x = scene.positions
    v = np.array([[0.0, -0.6, 0.27]])
    x1, v1 = guard_step(sim, x, v, 1.0 / 60.0)
    assert np.array_equal(x1, x)
    np.testing.assert_allclose(v1, [[0.0, 0.0, 0.27]], atol=1e-15)
    assert sim.contact_stats()["collider_paths_cut"] == 1


# -- the stress set, small ------------------------------------------------------------------
def small_thrown(speed, gap=0.1):
    return lambda: thrown(speed, res=12, gap=gap)


@pytest.mark.slow
@pytest.mark.parametrize("integrator,jacobi", [("xpbd", False), ("vbd", True)])
def test_the_frame_rate_solvers_keep_the_planes_inside_their_iterations(f32, integrator,
                                                                         jacobi, monkeypatch):
    """Two 12 x 12 cloths thrown at each other at 10 m/s, one step of 1/60 per frame and
    one substep: with the contact stage's planes inside the iterations
    (``ContactStage.search_solve``, ``ContactStage.keep_apart``) the run has no crossing, keeps
    the layers' order and leaves the guard less to correct: without them (the planes'
    list emptied) the guard moved 795 vertex pairs apart after either solver, with them
    26 after XPBD and 553 after VBD (whose Jacobi self-contact terms and Newton steps
    move vertices past the planes between their passes; counted as the sweeps then did).
    With the guard's Jacobi projection (as on GPUs) too: its velocity passes remove the
    approach of every vertex pair a position pass moved. Removing it in the position
    passes, by each one's partial share, let these layers swap (0 crossings, the order
    lost); removing it only where pairs ended on their planes tore the 64 x 64 fold with
    VBD at its second step (strain 1.03)."""
    monkeypatch.setattr(projection, "JACOBI", jacobi)

    def run():
        return run_case("thrown_10", integrator, 1.0 / 60.0, seconds=0.1,
                        build=small_thrown(10.0), options={"substeps": 1})
    with_planes = run()
    assert with_planes["blew_up"] is None
    assert with_planes["crossings_max"] == 0 and with_planes["order_kept"], with_planes
    monkeypatch.setattr(stage_module.ContactStage, "follow_solve",
                        lambda self, x0, x, choose=False: (
                            self.solve_list[0], self.planes_of(self.solve_list[0]), 0))
    without = run()
    assert without["blew_up"] is None and without["crossings_max"] == 0
    share = 0.05 if integrator == "xpbd" else 0.8
    assert with_planes["guard_corrections"] < share * without["guard_corrections"]


@pytest.mark.slow
def test_vbds_substeps_end_on_the_planes_the_guard_checks(f32):
    """Two 24 x 24 cloths thrown at each other at 3 m/s, VBD at its defaults at dt = 1/60
    (3 substeps): every spring within 10 % of its rest length after each step of the
    first 0.1 s (NumPy). The guard checks a step's motion against the pairs' planes at the
    step's start, and its moves are answered by no spring: where VBD's substeps kept only
    the planes of their own starts, the solve left the cloth stretched 1.2 % and the guard
    20 % (3.2 % with the step's planes kept in every substep)."""
    scene, x, v, _ = thrown(3.0, res=24)
    sim = tcloth.Simulator(scene, "vbd", dt=1 / 60)
    sim.set_state(positions=x, velocities=v)
    pairs, rest = scene.springs["pairs"], scene.springs["rest_length"]
    for _ in range(6):
        sim.step()
        y = sim.positions()
        assert (np.linalg.norm(y[pairs[:, 0]] - y[pairs[:, 1]], axis=1) / rest).max() < 1.1


@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["xpbd", "vbd", "projective"])
def test_self_collision_does_not_hold_a_falling_cloth_back(f32, integrator):
    """A 16 x 16 cloth dropped flat from 0.5 m at one step per frame falls as far in
    0.25 s with self-collision as without it (mean height within 1 mm): the planes cap
    only motion toward a neighbour, not the motion a cloth shares (Offset Geometric
    Contact's isotropic bounds held a falling cloth to a quarter of its fall)."""
    heights = []
    for on in (True, False):
        scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0))
        scene.add_cloth(resolution=(16, 16), size=(0.5, 0.5), center=(0.0, 0.5, 0.0),
                        mass=0.1, **CLOTH)
        scene.add_plane((0.0, 0.0, 0.0), (0.0, 1.0, 0.0))
        if on:
            scene.set_self_collision(thickness=0.006)
        sim = tcloth.Simulator(scene, integrator, dt=1.0 / 60.0)
        sim.step(15)
        heights.append(float(sim.positions()[:, 1].mean()))
    assert heights[0] < 0.5 - 0.25, heights            # it fell
    assert abs(heights[0] - heights[1]) < 1e-3, heights


@pytest.mark.slow
@pytest.mark.parametrize("integrator,dt", [
    ("backward_euler", 1.0 / 60.0), ("projective", 1.0 / 60.0), ("vbd", 1.0 / 60.0),
    ("vbd:bounds", 1.0 / 60.0), ("xpbd", 1.0 / 60.0), ("rk4", None)])
def test_thrown_cloths_never_cross_at_any_step(f32, integrator, dt):
    """Two 12 x 12 cloths thrown at each other at 10 m/s relative: zero crossings after
    every step, the layer order kept, no blow-up (float32). The explicit integrators, at
    their own dt of 5e-5 s, start 3 cm apart instead of 10 (they meet after 2.4 ms, not
    9.4) and run 8 ms, 160 steps: RK4 here, whose stages the contact forces enter four
    times; the other explicit integrators meet the same stage at the step's end
    (``tools/bench_contact.py --cases thrown_10`` runs every integrator, at 1/60 and
    1/240 where implicit)."""
    integrator, _, flag = integrator.partition(":")      # vbd:bounds: VBD with bounds=True
    options = {flag: True} if flag else {}
    if integrator in ("vbd", "xpbd"):
        options["substeps"] = "auto"       # one substep tears the cloths (and says so)
    r = run_case("thrown_10", integrator, dt, seconds=0.1 if dt else 0.008,
                 build=small_thrown(10.0, gap=0.1 if dt else 0.03), options=options)
    assert r["blew_up"] is None
    assert r["crossings_start"] == 0 and r["crossings_max"] == 0, r
    assert r["order_kept"], r
    assert r["closing_speed_end"] < 5.0, "the cloths never met"


@pytest.mark.slow
@pytest.mark.parametrize("integrator,dt,collider", [
    ("backward_euler", 1.0 / 60.0, "box"), ("projective", 1.0 / 60.0, "sphere"),
    ("vbd", 1.0 / 60.0, "box"), ("symplectic_euler", 1e-4, "box")])
def test_cloth_falling_at_10_m_per_s_stays_out_of_thin_colliders(f32, integrator, dt, collider):
    """A cloth thrown down at 10 m/s onto a box 1 cm thick or a sphere: no particle ends a
    step inside a collider, no step's path goes through the box, no cloth crossing, each
    checked after every step. Symplectic Euler at 1e-4 s starts 4.5 cm above the box
    instead of 19.5 (it lands after 4.5 ms) and runs 15 ms, 150 steps. At one step per
    frame the 24 x 24 cloth of the benchmark, 0.4 s: the cases where the guard's last
    projection round could leave held particles inside the box, and where a particle
    resting on the sphere within rounding of its surface has a ray cast that finds no
    entry (docs/contact.md). Each collider with two kinds of solver here; every
    integrator on both: ``python tools/bench_contact.py --cases box_10,sphere_10``."""
    frame = dt > 1e-3
    # the real-time solvers on the 12 x 12 cloth (their own tests cover the solve)
    res = 24 if frame and integrator not in ("vbd", "xpbd") else 12
    # VBD and XPBD with the substeps that follow this cloth's stress wave (one substep
    # tears it, and the instability test says so); landing at 10 m/s, this soft cloth
    # stretches by up to 70 % even in backward Euler's step, so the strain bound is 2
    options = {"strain_bound": 2.0}
    if integrator in ("vbd", "xpbd"):
        options["substeps"] = "auto"
    r = run_case(f"{collider}_10", integrator, dt, seconds=0.4 if frame else 0.015,
                 build=lambda: falling(collider, res=res, height=0.3 if frame else 0.15),
                 options=options)
    assert r["blew_up"] is None
    # it reached the collider: paths cut by the guard, or (VBD, whose solve takes the
    # collider's penalty) particles resting within its offset of 5 mm
    assert r["collider_paths_cut"] > 0 or r["closest_collider_m"] < 0.005, r
    assert r["inside_max"] <= 1e-6, r
    assert r["through"] == 0 and r["crossings_max"] == 0, r


@pytest.mark.slow
def test_displacement_bounds_keep_any_moves_inside_them_crossing_free(f64):
    """Offset Geometric Contact's bounds over the proximity list, on the folded cloth of
    the benchmark: each radius is at most gamma times the distance to any particle three
    mesh edges away or more (its triangles are then never excluded pairs), and moving
    every particle by its whole radius, in random directions or each toward its nearest
    such particle, crosses nothing (NumPy count)."""
    from tcloth.contact.bounds import GAMMA, DisplacementBounds
    from tcloth.contact.topology import contact_topology
    from tcloth.app.script import load_script
    module = load_script(os.path.join(HERE, "..", "scenes", "fold.py"))[0]
    x40, v40 = folding.folded_state(module, os.path.join(HERE, "..", "tools", "data",
                                                     "fold_40x40.npz"))
    n = 24
    scene = folding.fold_scene(module, n)
    # the saved fold resampled (no step: the stage's list is built at set_state)
    sim = tcloth.Simulator(scene, "symplectic_euler", dt=1e-4)
    sim.set_state(positions=folding.resample(x40, n), velocities=folding.resample(v40, n))
    x = sim.positions()
    assert count_crossings(x, scene.triangles) == 0
    bounds = DisplacementBounds(sim.model.inv_mass)
    sim.contact.detect_bounds(bounds, sim.state.x)
    radius = bounds.radius.to_numpy()
    # graph distance >= 3 from each particle, by breadth-first rings of the mesh edges
    topo = contact_topology(scene)
    near = [set(topo["neighbours"][topo["start"][i]:topo["start"][i + 1]]) | {i}
            for i in range(len(x))]
    dist = np.linalg.norm(x[:, None] - x[None], axis=2)
    for p in range(len(x)):
        two_rings = set().union(*(near[q] for q in near[p]))
        far = np.setdiff1d(np.arange(len(x)), list(two_rings))
        assert 0.0 < radius[p] <= GAMMA * dist[p, far].min() * (1 + 1e-9)
    rng = np.random.default_rng(5)
    for _ in range(3):
        d = rng.normal(size=x.shape)
        moved = x + radius[:, None] * d / np.linalg.norm(d, axis=1, keepdims=True)
        assert count_crossings(moved, scene.triangles) == 0
    masked = np.where(np.eye(len(x), dtype=bool) | (dist == 0), np.inf, dist)
    for p in range(len(x)):
        masked[p, list(set().union(*(near[q] for q in near[p])))] = np.inf
    toward = x[masked.argmin(axis=1)] - x
    moved = x + radius[:, None] * toward / np.linalg.norm(toward, axis=1, keepdims=True)
    assert count_crossings(moved, scene.triangles) == 0


def crossed_at_start():
    """Two 12 x 12 cloths through each other (one in xz, one in xy), sliding apart."""
    scene = tcloth.Scene(gravity=(0.0, 0.0, 0.0))
    a = scene.add_cloth(resolution=(12, 12), size=(0.4, 0.4), center=(0.0, 0.0, 0.0),
                        mass=0.1, **CLOTH)
    b = scene.add_cloth(resolution=(12, 12), size=(0.4, 0.4), center=(0.05, 0.0, 0.0),
                        plane="xy", mass=0.1, **CLOTH)
    scene.set_self_collision(thickness=0.006)
    v = np.zeros_like(scene.positions)
    v[a.particles.ravel(), 0] = 1.0
    v[b.particles.ravel(), 1] = 1.0
    return scene, scene.positions, v, (a, b)


@pytest.mark.slow
@pytest.mark.parametrize("integrator,dt", [("backward_euler", 1.0 / 60.0)])
def test_a_scene_that_starts_crossed_gets_no_worse(f32, integrator, dt):
    """Pairs that touch or cross at a step's start have no separating plane and are left
    as they are; the others are kept apart: the crossing count never grows, nothing blows
    up, and the fail-safe is not needed. Holding the crossed pairs while the cloths slide
    apart stretches their springs: the first step's total energy is 3.3 times the
    start's (0.13 -> 0.44 J), which the energy budget would stop; it is off here."""
    r = run_case("thrown_3", integrator, dt, seconds=0.2, build=crossed_at_start,
                 options={"energy_bound": False})
    assert r["crossings_start"] > 0
    assert r["blew_up"] is None
    assert r["crossings_max"] <= r["crossings_start"], r
    assert r["failsafe_steps"] == 0


@pytest.mark.slow
def test_the_fold_bench_counts_crossings_after_every_step(f32, monkeypatch):
    """tools/bench_self_collision.py --implicit reports the worst crossing count over every
    step of the run with self-collision, whatever the solver (not only at the end, nor only
    for the solvers with CG iterations): with XPBD, which has none, it counts the positions
    after each of three steps, and reports the worst."""
    from tcloth.app.script import load_script
    module = load_script(os.path.join(HERE, "..", "scenes", "fold.py"))[0]
    x40, v40 = folding.folded_state(module, os.path.join(HERE, "..", "tools", "data",
                                                     "fold_40x40.npz"))
    seen = []

    def count(positions, triangles, edges=None):
        seen.append(np.array(positions))
        return {1: 0, 2: 5, 3: 1}[len(seen)]
    monkeypatch.setattr(folding, "count_crossings", count)
    out = folding.one_second(module, x40, v40, 8, "xpbd", 1.0 / 60.0, 3.0 / 60.0, {})
    assert len(seen) == 3 and out["crossings_max"] == 5, out
    assert not np.array_equal(seen[0], seen[1]) and not np.array_equal(seen[1], seen[2])


# -- statistics -----------------------------------------------------------------------------
@pytest.mark.slow
def test_contact_stats_count_what_the_stage_did(f32):
    """A cloth thrown onto a box in one batch of 600 substeps (the collider sweep runs inside
    the batch kernel), then two crossed cloths: the statistics and the viewer's lines. The
    paths cut are counted from outside: the same run again a step at a time (bit for bit
    the batch's), where a particle the sweep stopped on the box's top ends its step with
    its vertical velocity removed, exactly 0."""
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(8, 8), size=(0.6, 0.6), center=(0.0, 0.3, 0.0), mass=0.2,
                    **CLOTH)
    scene.add_box((0.0, 0.1, 0.0), (0.25, 0.005, 0.25), friction=0.3)
    sim = tcloth.Simulator(scene, dt=1e-4)
    v0 = np.tile([0.0, -10.0, 0.0], (scene.num_particles, 1))
    sim.set_state(velocities=v0)
    assert sim.fusion() is None
    sim.step(600)
    stats = sim.contact_stats()
    assert set(stats) == set(stage_module.STATS) | {"point_triangle", "edge_edge", "collider"}
    # no self-collision: the guard had no pairs to move apart
    assert [stats[k] for k in ("candidates", "rebuilds", "swept_searches", "guard_corrections",
                               "guard_sweeps", "failsafe_steps", "failsafe_vertices")] == [0] * 7
    x_batch = sim.positions()
    sim.reset()
    sim.set_state(velocities=v0)
    stopped = 0
    for _ in range(600):
        sim.step()
        stopped += int((sim.velocities()[:, 1] == 0.0).sum())
    assert np.array_equal(sim.positions(), x_batch)
    # each particle over the box's top (36 of the 8 x 8) was stopped at least once
    over = int((np.abs(scene.positions[:, [0, 2]]) < 0.25).all(axis=1).sum())
    assert stats["collider_paths_cut"] == stopped >= over == 36, (stats, stopped)
    # the cloth lies on the box: the particles within a collider's thickness, by NumPy
    phi = signed_distances(scene, sim.positions().astype(np.float64), sim.time)
    thickness = np.array([c["thickness"] for c in scene.colliders])
    assert stats["collider"] == int((phi < thickness).any(axis=1).sum()) > 0
    lines = contact_lines(stats)
    assert any("collider contacts" in line for line in lines)
    assert not any("self-contacts" in line for line in lines)

    crossed, x, v, _ = crossed_at_start()
    # a step from Python: the stage's wall time is counted outside batch kernels only
    sim = tcloth.Simulator(crossed, dt=1e-4, batch=False)
    sim.step()
    stats = sim.contact_stats()
    assert stats["rebuilds"] >= 1 and stats["candidates"] > 0 and stats["seconds"] > 0.0
    assert stats["point_triangle"] + stats["edge_edge"] > 0 and stats["collider"] == 0
    assert any("self-contacts" in line for line in contact_lines(stats))
    no_contact = tcloth.Scene()
    no_contact.add_cloth(resolution=(4, 4), size=(0.2, 0.2), **CLOTH)
    assert tcloth.Simulator(no_contact).contact_stats() == {}
    assert contact_lines({}) == []


@pytest.mark.slow
def test_the_swept_list_holds_every_pair_that_can_meet_on_a_motion_it_holds(f64):
    """A near swept search (``contact/swept.py``) lists each point-triangle and edge-edge
    pair once whose swept boxes meet and whose gap at the searched start less the longest
    relative displacement of a vertex pair across its sides is within the thickness plus
    twice the margin, as a NumPy brute force finds them; that leaves out a good part of
    the pairs whose boxes meet (here 44 %: pairs moving together, or apart). On straight
    motions whose every particle starts and ends within the margin of its searched start
    and end (``holds``), no pair left out comes within the thickness (sampled along each
    motion); a motion that takes a particle beyond its margin is not held."""
    from test_self_collision import CLOTH as SHEET, pair_key, point_triangle, segment_segment
    from tcloth.contact.swept import search_step
    rng = np.random.default_rng(3)
    scene = tcloth.Scene(gravity=(0, 0, 0))
    for k in range(3):
        scene.add_cloth(resolution=(6, 6), size=(0.3, 0.3), center=(0, 0.03 * k, 0),
                        plane="xz", **SHEET)
    thickness, margin = 0.01, 0.004
    scene.set_self_collision(thickness=thickness)
    sim = tcloth.Simulator(scene)
    swept = sim.contact.swept
    x0 = scene.positions + rng.normal(scale=0.003, size=scene.positions.shape)
    layer = np.repeat(np.arange(3), 36)[:, None]
    # the outer layers close on the middle one by 1 cm each, which turns a little; a
    # third of the particles jitter besides
    x1 = (x0 + [0.0, -0.01, 0.0] * (layer - 1) + 0.1 * np.cross([0, 1, 0], x0) * (layer == 1)
          + (rng.random((len(x0), 1)) < 0.3) * rng.normal(scale=0.004, size=x0.shape))
    ends = [sim.model.state() for _ in range(2)]

    def motion(a, b):
        ends[0].x.from_numpy(a)
        ends[1].x.from_numpy(b)
        return ends[0].x, ends[1].x
    count = search_step(swept, *motion(x0, x1), thickness, margin, near=True)
    cl = swept.candidates
    listed = [pair_key(i, k) for i, k in zip(cl.ids.to_numpy()[:count],
                                             cl.kind.to_numpy()[:count])]
    points, triangles, edges = (getattr(swept.table, k).to_numpy() for k in
                                ("points", "triangles", "edges"))
    near = []                   # the pairs sharing no particle whose swept boxes meet
    for kind, ids, split in (
            (0, np.array([[p, *t] for p in points for t in triangles if p not in t]), 1),
            (1, np.array([[*a, *b] for i, a in enumerate(edges) for b in edges[i + 1:]
                          if not set(a) & set(b)]), 2)):
        boxes = [np.concatenate([x0[s], x1[s]], axis=1) for s in (ids[:, :split],
                                                                   ids[:, split:])]
        (lo_a, lo_b), (hi_a, hi_b) = ([b.min(axis=1) for b in boxes],
                                      [b.max(axis=1) for b in boxes])
        grow = thickness + 2 * margin
        meet = ((lo_a <= hi_b + grow) & (lo_b <= hi_a + grow)).all(axis=1)
        near += [(i, kind, split) for i in ids[meet]]

    def gap(x, ids, kind):
        return point_triangle(*x[ids]) if kind == 0 else segment_segment(*x[ids])
    d = x1 - x0
    expected = {pair_key(ids, kind) for ids, kind, split in near
                if gap(x0, ids, kind) - max(np.linalg.norm(d[a] - d[b]) for a in ids[:split]
                                            for b in ids[split:]) <= thickness + 2 * margin}
    assert len(set(listed)) == len(listed) and set(listed) == expected
    assert 20 < len(expected) < 0.75 * len(near), (len(expected), len(near))
    left_out = [(ids, kind) for ids, kind, _ in near if pair_key(ids, kind) not in expected]

    def within_margin():
        e = rng.normal(size=x0.shape)
        return margin * rng.random((len(x0), 1)) * e / np.linalg.norm(e, axis=1, keepdims=True)
    for _ in range(4):
        a, b = x0 + within_margin(), x1 + within_margin()
        assert swept.holds(*motion(a, b))
        for ids, kind in left_out:
            assert min(gap(a + s * (b - a), ids, kind) for s in np.linspace(0, 1, 6)) > thickness
    b = x1.copy()
    b[40] += 1.5 * margin
    assert not swept.holds(*motion(x0, b))


# The sliding case (``tcloth.testing.contact_cases.sliding``): nothing pushes along the
# layers, neither the frictionless self-contact nor the frictionless floor, so the upper
# cloth keeps its speed and the two cloths their momentum along the slide. A contact force
# lies along the layers' normal, which the discretised cloths tilt only where they wrinkle:
# the target is the upper cloth's mean speed within 1 % of its start (docs/contact.md,
# tools/bench_sliding.py), and never above it.
KEPT = 0.99
SLOWED = "the sliding cloth is braked below 99 % of its speed (docs/contact.md, 'Open')"


@functools.lru_cache(maxsize=None)
def slid(integrator, small, steps):
    """(the upper cloth's mean speed along the slide, the momentum along it, the crossings)
    after ``steps`` steps of 1/60 s of the sliding case (``small``: a 6 x 6 cloth of 10 g
    over a 12 x 12 one, else the benchmark's 8 x 8 of 20 g over 24 x 24)."""
    scene, _, upper, v = sliding((12, 0.6, 0.15), (6, 0.2, 0.01)) if small else sliding()
    sim = tcloth.Simulator(scene, integrator, dt=1.0 / 60.0)
    sim.set_state(velocities=v)
    sim.step(steps)
    return (float(sim.velocities()[upper.particles.ravel(), 0].mean()),
            float(sim.momentum()[0][0]), count_crossings(sim.positions(), scene.triangles))


@pytest.mark.slow
@pytest.mark.parametrize("integrator", [
    "xpbd", pytest.param("projective", marks=pytest.mark.xfail(strict=True, reason=SLOWED))])
def test_a_cloth_slides_over_another_at_one_step_per_frame(f32, integrator):
    """A 6 x 6 cloth of 10 g thrown at 1 m/s across a 12 x 12 cloth lying on a
    frictionless floor, 9 mm above it (self-collision of 6 mm, no friction), 10 steps at
    1/60: the upper cloth keeps its speed within 1 % (KEPT). The separating planes take
    the layers' normal where the motion does not cross it (``contact/normals.py``), and
    XPBD's also where its prediction crosses both planes; with the closest points'
    direction always, the two grids' parallel edges braked it to 0.33 (XPBD) and 0.18 m/s
    (projective), and XPBD's substeps with the closest points' plane of a landing pair to
    0.41 m/s (``docs/contact.md``). Projective still brakes it."""
    speed, _, _ = slid(integrator, True, 10)
    assert KEPT <= speed <= 1.0 + 1e-3


@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["xpbd", "projective"])
def test_a_sliding_cloth_gains_no_speed_nor_the_layers_momentum(f32, integrator):
    """The same slide: no cloth passes through the other, the two cloths keep their
    momentum along the slide (0.01 kg m/s: no force along it but each other's), and the
    upper cloth goes no faster than it was thrown."""
    speed, momentum, crossings = slid(integrator, True, 10)
    assert speed <= 1.0 + 1e-3
    assert abs(momentum - 0.01) < 1e-4
    assert crossings == 0


@pytest.mark.slow
def test_vbd_converges_to_backward_eulers_step_in_contact(f64):
    """``tools/bench_sliding.py``'s case, smaller (a 6 x 6 cloth sliding at 1 m/s over a
    12 x 12 one), six backward Euler steps in, where the layers touch (180 contacts):
    one step from there with VBD (no Chebyshev, the inertial guess, one substep) ends
    within 2e-5 m of backward Euler's tightly solved step at 10 and 100 iterations, with
    its momentum along the slide within 2e-6 kg m/s of backward Euler's (which keeps it).
    A vertex's Newton step from outside the thickness, where the penalty is off, used to
    overshoot into contact and the iterations cycled: 4.8e-3 and 5.8e-3 m away, the
    momentum 1.8e-4 short at 100 iterations (``vbd_local.py``)."""
    def scene():
        return sliding((12, 0.6, 0.15), (6, 0.2, 0.01))
    first, _, _, v = scene()
    warm = tcloth.Simulator(first, "backward_euler", dt=1.0 / 60.0)
    warm.set_state(velocities=v)
    warm.step(6)
    x0, v0 = warm.positions(), warm.velocities()
    be = tcloth.Simulator(scene()[0], "backward_euler", dt=1.0 / 60.0, newton_tol=1e-12,
                          cg_tol=1e-12, newton_iterations=60)
    be.set_state(positions=x0, velocities=v0)
    be.step()
    assert sum(be.self_contacts().values()) > 100
    target, momentum = be.positions(), be.momentum()[0][0]
    assert abs(momentum - 0.01) < 1e-6
    vbd = tcloth.Simulator(scene()[0], "vbd", dt=1.0 / 60.0, rho=0.0, initial_guess="inertia",
                           substeps=1, batch=False, split=False)
    for iterations in (10, 100):
        vbd.set_integrator_options(iterations=iterations)
        vbd.set_state(positions=x0, velocities=v0)
        vbd.step()
        assert np.abs(vbd.positions() - target).max() < 2e-5, iterations
        assert abs(vbd.momentum()[0][0] - momentum) < 2e-6, iterations


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=SLOWED)
def test_projectives_velocity_pass_keeps_a_sliding_cloths_speed(f32):
    """``tools/bench_sliding.py``'s case with projective dynamics, 0.5 s at 1/60: the
    self-contact projection's velocity pass removes approach along the layers' normal
    (``normals.contact_normal``), not along the closest points' direction, which between
    offset edges tilts along the layers, so the upper cloth keeps its speed within 1 %
    (KEPT). It keeps 89 % (56 % with the closest points' direction): resting-contact
    jitter brakes it."""
    speed, _, _ = slid("projective", False, 30)
    assert KEPT <= speed <= 1.0 + 1e-3


@pytest.mark.slow
def test_projectives_velocity_pass_keeps_the_layers_momentum(f32):
    """The same 0.5 s: no crossing, both cloths' momentum along the slide kept (0.02 kg m/s)
    and the upper cloth no faster than it was thrown."""
    speed, momentum, crossings = slid("projective", False, 30)
    assert speed <= 1.0 + 1e-3
    assert abs(momentum - 0.02) < 1e-4
    assert crossings == 0
