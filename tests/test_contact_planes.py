"""Self-contact inside projective dynamics' global step (tcloth/contact/planes.py):
the planes' active vertex pairs, forces and matrix against a NumPy reference and finite
differences, and what they change at one step per frame against the same runs without
them (``planes=False``), side by side."""
import os

import numpy as np
import pytest
import taichi as ti

import tcloth
from tcloth import runtime
from tcloth.contact.search import POINT_TRIANGLE
from tcloth.grad import Trajectory
from tcloth.contact import planes as contact_planes

from tcloth.testing import folding
from tcloth.testing.contact_cases import CLOTH, run_case, thrown

HERE = os.path.dirname(os.path.abspath(__file__))

PAIRS = {POINT_TRIANGLE: ((0, 1), (0, 2), (0, 3))}
EDGE_PAIRS = ((0, 2), (0, 3), (1, 2), (1, 3))


def field(a):
    f = ti.Vector.field(3, runtime.real(), shape=a.shape[0])
    f.from_numpy(a.astype(runtime.numpy_real()))
    return f


def layers_pressed(seed=0):
    """Two 6 x 6 cloths 1 cm apart (thickness 6 mm) and a projective simulator; the
    stage's candidates of a motion that presses them to 2 mm with a jitter, and that
    pressed state. Returns (simulator, contacts, pressed positions)."""
    scene = tcloth.Scene(gravity=(0.0, 0.0, 0.0))
    for y in (0.005, -0.005):
        scene.add_cloth(resolution=(6, 6), size=(0.1, 0.1), center=(0.0, y, 0.0), mass=0.01,
                        **CLOTH)
    scene.set_self_collision(thickness=0.006)
    sim = tcloth.Simulator(scene, "projective", dt=1.0 / 60.0)
    x0 = scene.positions.astype(np.float64)
    pressed = x0.copy()
    pressed[:36, 1] -= 0.008
    pressed += np.random.default_rng(seed).normal(scale=5e-4, size=x0.shape)
    contacts = sim.contact.search_solve(field(x0), field(pressed))
    return sim, contacts, pressed


def reference(contacts, x, diagonal):
    """The active vertex pairs (a, b, n, the distance they are held at) and their
    weights, in NumPy."""
    cl, pl, rows = contacts
    ids, kind = cl.ids.to_numpy()[:rows], cl.kind.to_numpy()[:rows]
    n, delta = pl.n.to_numpy()[:rows], pl.delta.to_numpy()[:rows]
    active = []
    for c in range(rows):
        if delta[c] <= 0.0:
            continue
        for a, b in PAIRS.get(kind[c], EDGE_PAIRS):
            pa, pb = ids[c, a], ids[c, b]
            held = contact_planes.REACH * delta[c]
            if n[c] @ (x[pa] - x[pb]) < held:
                active.append((pa, pb, n[c], held))
    hits = np.zeros(len(x))
    for pa, pb, _, _ in active:
        hits[pa] += 1
        hits[pb] += 1
    w = [contact_planes.PLANE_STIFFNESS * min(diagonal[a] / hits[a], diagonal[b] / hits[b])
         for a, b, _, _ in active]
    return active, np.array(w)


def energy(active, w, x):
    return sum(wk / 2 * max(0.0, d - nk @ (x[a] - x[b])) ** 2
               for (a, b, nk, d), wk in zip(active, w))


def closest_gap(ids, kind, x):
    """The vector between a candidate's closest points at x, first side less second, in
    NumPy (brute force over a fine sampling of the triangle or the two edges)."""
    t = np.linspace(0.0, 1.0, 81)
    if kind == POINT_TRIANGLE:
        a, b, c = x[ids[1]], x[ids[2]], x[ids[3]]
        u, v = np.meshgrid(t, t)
        keep = u + v <= 1.0
        points = a + u[keep, None] * (b - a) + v[keep, None] * (c - a)
        d = x[ids[0]] - points
    else:
        p = x[ids[0]] + t[:, None] * (x[ids[1]] - x[ids[0]])
        q = x[ids[2]] + t[:, None] * (x[ids[3]] - x[ids[2]])
        d = (p[:, None, :] - q[None, :, :]).reshape(-1, 3)
    return d[np.argmin(np.linalg.norm(d, axis=1))]


def least_separation(ids, kind, x, n):
    """The least n . (x_a - x_b) over a candidate's vertex pairs across its sides."""
    return min(n @ (x[ids[a]] - x[ids[b]]) for a, b in PAIRS.get(kind, EDGE_PAIRS))


@pytest.mark.slow
def test_planes_between_two_layers_let_one_slide_over_the_other(f64):
    """Two flat cloths 9 mm apart (thickness 6 mm), the upper one shifted by half a
    spacing and moving 16.7 mm along the layers. Each candidate across them takes the
    layers' normal where the motion's end does not cross that plane, or crosses it less
    than its closest points' plane (``normals.normal_margin``), checked against NumPy:
    more than ten of them have closest points whose direction tilts by more than 18
    degrees (the planes that braked a cloth sliding over another), yet take the
    layers' normal. Every plane with a margin separates
    its candidate's vertex pairs by at least its delta at x0; candidates within a layer
    keep their closest points' direction (in the layer)."""
    thickness = 0.006
    scene = tcloth.Scene(gravity=(0.0, 0.0, 0.0))
    spacing = 0.1 / 5
    lower = scene.add_cloth(resolution=(6, 6), size=(0.1, 0.1), center=(0.0, 0.0, 0.0),
                            mass=0.01, **CLOTH)
    scene.add_cloth(resolution=(6, 6), size=(0.1, 0.1), mass=0.01, **CLOTH,
                    center=(spacing / 2, 0.009, spacing / 2))
    scene.set_self_collision(thickness=thickness)
    sim = tcloth.Simulator(scene, "projective", dt=1.0 / 60.0)
    x0 = scene.positions.astype(np.float64)
    moved = x0.copy()
    moved[36:, 0] += 1.0 / 60.0
    cl, pl, rows = sim.contact.search_solve(field(x0), field(moved))
    ids, kind = cl.ids.to_numpy()[:rows], cl.kind.to_numpy()[:rows]
    n, delta = pl.n.to_numpy()[:rows], pl.delta.to_numpy()[:rows]
    low = set(lower.particles.ravel().tolist())
    def margin(d):
        return min(thickness, max(0.5 * d, 0.25 * thickness))
    across, layered, tilted = 0, 0, 0
    for c in range(rows):
        if delta[c] == 0.0:
            continue
        if delta[c] > 0.0:
            assert least_separation(ids[c], kind[c], x0, n[c]) >= delta[c] * (1 - 1e-9)
        if len({ids[c, k] in low for k in range(4)}) == 1:
            assert abs(n[c, 1]) < 1e-9
            continue
        across += 1
        g = closest_gap(ids[c], kind[c], x0)
        closest = g / np.linalg.norm(g)
        up = np.array([0.0, np.sign(closest[1]), 0.0])
        s = least_separation(ids[c], kind[c], x0, up)
        closest_room = least_separation(ids[c], kind[c], moved, closest) - \
            margin(np.linalg.norm(g))
        up_room = least_separation(ids[c], kind[c], moved, up) - margin(s)
        assert s >= min(0.5 * np.linalg.norm(g), 0.5 * thickness)
        if up_room >= 1e-9 or up_room > closest_room + 1e-3 * thickness + 1e-9:
            layered += 1
            tilted += closest[1] ** 2 < 0.9
            np.testing.assert_allclose(n[c], up, atol=1e-9)
        elif up_room < -1e-9 and up_room < closest_room + 1e-3 * thickness - 1e-9:
            np.testing.assert_allclose(n[c], closest, atol=2e-3)
    assert across > 20 and layered > 10 and tilted > 10, (across, layered, tilted)


@pytest.mark.slow
def test_the_planes_forces_and_matrix_match_numpy_and_finite_differences(f64):
    """The kernels' active pairs, forces f = -grad E with E = sum w/2 min(0, n.(x_a - x_b)
    - REACH delta)^2 (central differences of a NumPy E) and product H v (central
    differences of the kernels' own forces), on two layers pressed into each other's
    planes."""
    sim, contacts, x = layers_pressed()
    n = x.shape[0]
    planes = sim.integrator.planes
    diagonal = ti.field(runtime.real(), shape=n)
    diag = 1.0 + np.random.default_rng(1).random(n)
    diagonal.from_numpy(diag)

    def forces(y):
        out = field(np.zeros_like(y))
        planes.gather(contacts, field(y), sim.model.inv_mass, diagonal)
        planes.add_forces(field(y), out)
        return out.to_numpy()

    active, w = reference(contacts, x, diag)
    assert len(active) > 50                                  # the layers were pressed
    f = forces(x)
    assert planes.count[None] == len(active)
    eps = 1e-7
    rng = np.random.default_rng(2)
    for _ in range(3):
        d = rng.normal(size=x.shape)
        slope = (energy(active, w, x + eps * d) - energy(active, w, x - eps * d)) / (2 * eps)
        assert abs(-np.sum(f * d) - slope) < 1e-6 * (abs(slope) + 1.0)
    v = rng.normal(size=x.shape)
    out = field(np.zeros_like(x))
    forces(x)
    planes.add_product(field(v), out, True)
    fd = -(forces(x + eps * v) - forces(x - eps * v)) / (2 * eps)
    assert np.allclose(out.to_numpy(), fd, atol=1e-6 * np.abs(fd).max())
    assert np.allclose(f.sum(axis=0), 0.0, atol=1e-12)       # equal and opposite


@pytest.mark.slow
def test_projective_holds_thrown_cloths_apart_inside_its_step(f32):
    """Two 12 x 12 cloths thrown at each other at 10 m/s, one step of 1/60 per frame:
    with the planes in projective dynamics' step the run has no crossing, keeps the
    layers' order and the momentum, and leaves the guard a small share of what it
    corrects without them (the solve arrives without crossings); the cloths end together
    (the planes' contact is inelastic, as backward Euler's is)."""
    runs = {}
    for planes in (True, False):
        runs[planes] = run_case("thrown_10", "projective", 1.0 / 60.0, seconds=0.1,
                                build=lambda: thrown(10.0, res=12),
                                options={"planes": planes})
    with_planes, without = runs[True], runs[False]
    for r in runs.values():
        assert r["blew_up"] is None and r["crossings_max"] == 0 and r["order_kept"], r
    assert with_planes["guard_corrections"] < 0.1 * without["guard_corrections"], runs
    assert with_planes["momentum_drift"] < 1e-3, with_planes
    assert abs(with_planes["closing_speed_end"]) < 0.2, with_planes


def test_a_gradient_of_projective_leaves_its_planes_out(f32):
    """The adjoint of projective dynamics' step does not hold the planes: a trajectory
    runs without them, and asking for them says so."""
    scene = thrown(10.0, res=4)[0]
    assert not Trajectory(scene, 2, 1.0 / 60.0, "projective").sim.integrator.has_planes
    with pytest.raises(tcloth.SceneError, match="planes=True"):
        Trajectory(scene, 2, 1.0 / 60.0, "projective", planes=True)


@pytest.mark.slow
def test_the_deflated_solve_solves_the_same_system_in_fewer_iterations(f64):
    """The planes' second level (``integrators/deflation.py``) on the folded cloth at one
    step per frame: its E equals U^T A U with A applied by the solver's own product to
    each active pair's column u = (n on a, -n on b), and a global solve with it solves
    A x = b (a random b; the residual by that product) as the V-cycle alone does, in
    fewer CG iterations."""
    from tcloth.app.script import load_script
    module = load_script(os.path.join(HERE, "..", "scenes", "fold.py"))[0]
    x40, v40 = folding.folded_state(module, os.path.join(HERE, "..", "tools", "data",
                                                     "fold_40x40.npz"))
    n = 16
    sim = tcloth.Simulator(folding.fold_scene(module, n), "projective", dt=1.0 / 60.0)
    sim.set_state(positions=folding.resample(x40, n), velocities=folding.resample(v40, n))
    sim.step(3)
    integrator = sim.integrator
    solver, deflation, rows = integrator.solver, integrator.deflation, integrator.planes.rows
    k = deflation.count
    assert k > 5, k
    count = sim.model.particle_count
    free = np.repeat(sim.model.inv_mass.to_numpy() > 0, 3)
    v_in, out = field(np.zeros((count, 3))), field(np.zeros((count, 3)))

    def apply(v):
        v_in.from_numpy(v.reshape(count, 3))
        solver.apply(v_in, out)
        return out.to_numpy().ravel()
    columns = np.zeros((k, count, 3))
    for i, ((p, q), normal) in enumerate(zip(rows.pairs.to_numpy()[:k], rows.n.to_numpy()[:k])):
        columns[i, p] += normal
        columns[i, q] -= normal
    u = columns.reshape(k, -1) * free
    springs, gram, w = np.zeros((k, k)), np.zeros((k, k)), np.zeros(k)
    deflation._blocks(rows, k, springs, gram, w)
    expected = u @ np.stack([apply(column) * free for column in u]).T
    np.testing.assert_allclose(springs + gram @ (w[:, None] * gram), expected, rtol=0,
                               atol=1e-10 * np.abs(expected).max())
    b = np.zeros(3 * count)
    b[free] = np.random.default_rng(2).normal(size=free.sum())
    solutions, iterations = [], []
    for deflated in (k, 0):
        deflation.count = deflated
        solver.b.from_numpy(b.reshape(count, 3))
        iterations.append(solver.solve(1e-10, 2000)[0])
        solutions.append(solver.x.to_numpy().ravel())
        assert np.linalg.norm((apply(solutions[-1]) - b)[free]) < 1e-9 * np.linalg.norm(b)
    np.testing.assert_allclose(solutions[0], solutions[1], rtol=0,
                               atol=1e-7 * np.abs(solutions[1]).max())
    assert iterations[0] < 0.8 * iterations[1], (k, iterations)
