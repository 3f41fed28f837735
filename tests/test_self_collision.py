"""Self-collision: cloth against itself and other cloth (tcloth/terms/self_contact.py),
checked against NumPy geometry (distances, segment-triangle crossings), conservation laws
and finite differences."""
import numpy as np
import pytest

import tcloth
from tcloth import SceneError
from tcloth.contact.topology import contact_topology

from conftest import energy_gradient, scene_module

CLOTH = {"mass": 0.1, "structural": (400.0, 0.05), "shear": (80.0, 0.02),
         "flexion": (10.0, 0.005), "pinned": []}


# -- NumPy references -------------------------------------------------------------------------
def point_segment(p, a, b):
    ab = b - a
    t = np.clip(np.dot(p - a, ab) / np.dot(ab, ab), 0.0, 1.0)
    return np.linalg.norm(p - (a + t * ab))


def point_triangle(p, a, b, c):
    """Distance from p to triangle abc: to its plane where p projects inside, else to the
    nearest edge."""
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n)
    q = p - np.dot(p - a, n) * n
    inside = all(np.dot(np.cross(v1 - v0, q - v0), n) >= 0 for v0, v1 in ((a, b), (b, c), (c, a)))
    if inside:
        return abs(np.dot(p - a, n))
    return min(point_segment(p, a, b), point_segment(p, b, c), point_segment(p, c, a))


def segment_segment(p0, p1, q0, q1):
    """Distance between two segments: the interior stationary point where it lies in
    [0,1]^2, else the nearest endpoint-to-segment distance."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    m = np.array([[d1 @ d1, -d1 @ d2], [-d1 @ d2, d2 @ d2]])
    best = min(point_segment(p0, q0, q1), point_segment(p1, q0, q1),
               point_segment(q0, p0, p1), point_segment(q1, p0, p1))
    if abs(np.linalg.det(m)) > 1e-12:
        s, u = np.linalg.solve(m, [-(d1 @ r), d2 @ r])
        if 0 <= s <= 1 and 0 <= u <= 1:
            best = min(best, np.linalg.norm(p0 + s * d1 - q0 - u * d2))
    return best


def numpy_energy(scene, x, thickness, k):
    """The self-contact energy by brute force over every pair the exclusion rule keeps."""
    topo = contact_topology(scene)
    nb = [set(topo["neighbours"][topo["start"][i]:topo["start"][i + 1]]) | {i}
          for i in range(scene.num_particles)]

    def excluded(side_a, side_b):
        return any(b in nb[a] for a in side_a for b in side_b)

    def penalty(d):
        return 0.5 * k * (thickness - d) ** 2 if d < thickness else 0.0
    e = 0.0
    for p in topo["points"]:
        for tri in topo["triangles"]:
            if not excluded([p], tri):
                e += penalty(point_triangle(x[p], *x[tri]))
    edges = topo["edges"]
    for i in range(len(edges)):
        for j in range(i + 1, len(edges)):
            if not excluded(edges[i], edges[j]):
                e += penalty(segment_segment(*x[edges[i]], *x[edges[j]]))
    return e


def crossings(x, edges, triangles):
    """How many (edge, triangle) pairs without a shared particle intersect (Moller-Trumbore
    on every pair, NumPy)."""
    a, b, c = (x[triangles[:, k]][None] for k in range(3))
    o = x[edges[:, 0]][:, None]
    d = (x[edges[:, 1]] - x[edges[:, 0]])[:, None]
    e1, e2 = b - a, c - a
    pv = np.cross(d, e2)
    det = np.einsum("ijk,ijk->ij", e1 * np.ones_like(pv), pv)
    ok = np.abs(det) > 1e-14
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    tv = o - a
    u = np.einsum("ijk,ijk->ij", tv, pv) * inv
    qv = np.cross(tv, e1 * np.ones_like(tv))
    v = np.einsum("ijk,ijk->ij", d * np.ones_like(qv), qv) * inv
    t = np.einsum("ijk,ijk->ij", e2 * np.ones_like(qv), qv) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t >= 0) & (t <= 1)
    shared = (edges[:, None, :, None] == triangles[None, :, None, :]).any(axis=(2, 3))
    return int((hit & ~shared).sum())


# -- scenes ---------------------------------------------------------------------------------
def two_layers(self_collision, res=10, thickness=0.01):
    """Two cloths on a plane, the top one offset by half a grid spacing in x and z."""
    scene = tcloth.Scene()
    h = 1.0 / (res - 1)
    low = scene.add_cloth(resolution=(res, res), center=(0, 0.02, 0), plane="xz", **CLOTH)
    top = scene.add_cloth(resolution=(res, res), center=(h / 2, 0.05, h / 2), plane="xz",
                          **CLOTH)
    scene.add_plane(friction=0.3)
    if self_collision:
        scene.set_self_collision(thickness=thickness)
    return scene, low, top


@pytest.mark.slow
def test_top_cloth_rests_a_thickness_above_the_lower_one(f64):
    """With self-collision the top cloth's particles (above the lower cloth's quads) come to
    rest a thickness above it; without, both cloths lie in the same layer on the plane."""
    heights = {}
    for on in (True, False):
        scene, low, top = two_layers(on)
        sim = tcloth.Simulator(scene, dt=2e-4)
        sim.step(2500)
        y = sim.positions()[:, 1]
        # the top cloth overhangs the lower one by half a spacing at +x and +z and drapes
        # over its border there: the rows next to it are left out
        heights[on] = (y[low.particles], y[top.particles[:-2, :-2]])
        if on:
            assert sim.self_contacts()["point_triangle"] > 0
            assert sim.energy()["self_contact"] > 0
    plane, thickness = 0.005, 0.01
    low_on, top_on = heights[True]
    np.testing.assert_allclose(low_on, plane, atol=1e-3)
    np.testing.assert_allclose(top_on, plane + thickness, atol=2e-3)
    low_off, top_off = heights[False]
    np.testing.assert_allclose(low_off, plane, atol=1e-3)
    np.testing.assert_allclose(top_off, plane, atol=1e-3)


def colliding_cloths(res=8, speed=2.0):
    """Two cloths in zero gravity flying at each other, one turned 45 degrees about the
    vertical and tilted."""
    scene = tcloth.Scene(gravity=(0, 0, 0))
    a = scene.add_cloth(resolution=(res, res), size=(0.6, 0.6), center=(0, 0.1, 0), plane="xz",
                        **CLOTH)
    b = scene.add_cloth(resolution=(res, res), size=(0.6, 0.6), center=(0.05, -0.1, 0.03),
                        plane="xz", **CLOTH)
    x = scene.positions
    ids = b.particles.ravel()
    c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
    rot = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]) @ np.array(
        [[1, 0, 0], [0, np.cos(0.2), -np.sin(0.2)], [0, np.sin(0.2), np.cos(0.2)]])
    centre = x[ids].mean(0)
    x[ids] = (x[ids] - centre) @ rot.T + centre
    v = np.zeros_like(x)
    v[a.particles.ravel(), 1] = -speed
    v[ids, 1] = speed
    moved = tcloth.Scene(gravity=(0, 0, 0))
    moved.add_particles(x, mass=scene.masses, velocities=v)
    return scene, moved, x, v


@pytest.mark.slow
@pytest.mark.parametrize("integrator,dt,options", [
    ("symplectic_euler", 1e-4, {}),
    # solved tightly: backward Euler conserves momentum where grad E = 0
    ("backward_euler", 1e-3, {"newton_tol": 1e-9, "newton_iterations": 40, "cg_tol": 1e-8})])
def test_cloths_thrown_at_each_other_never_cross_and_keep_momentum(f64, integrator, dt,
                                                                   options):
    scene, _, x, v = colliding_cloths()
    scene.set_self_collision(thickness=0.02)
    sim = tcloth.Simulator(scene, integrator, dt=dt, **options)
    sim.set_state(positions=x, velocities=v)
    topo = contact_topology(scene)
    p0 = sim.momentum()[0]
    hits, contacts = [], 0
    for _ in range(12):
        sim.step(int(round(0.01 / dt)))
        hits.append(crossings(sim.positions(), topo["edges"], topo["triangles"]))
        contacts = max(contacts, sum(sim.self_contacts().values()))
    assert contacts > 10, "the cloths never met"
    assert hits == [0] * 12
    scale = float(np.sum(scene.masses)) * 2.0
    np.testing.assert_allclose(sim.momentum()[0], p0, atol=1e-9 * scale)


@pytest.mark.slow
def test_without_self_collision_the_thrown_cloths_pass_through():
    """The crossing count sees the failure that self-collision prevents."""
    tcloth.init(precision="f64")
    scene, _, x, v = colliding_cloths()
    sim = tcloth.Simulator(scene, dt=1e-4)
    sim.set_state(positions=x, velocities=v)
    topo = contact_topology(scene)
    sim.step(500)
    assert crossings(sim.positions(), topo["edges"], topo["triangles"]) > 0


@pytest.mark.slow
def test_flat_hanging_cloth_moves_identically_with_and_without(f64):
    """Neighbours close by construction never repel: a cloth that never touches itself
    moves bit for bit as without self-collision."""
    runs = []
    for on in (False, True):
        scene = tcloth.Scene()
        cloth = scene.add_cloth(resolution=(12, 12), size=(0.5, 0.5), plane="xy",
                                mass=0.1, structural=(400.0, 0.05), shear=(80.0, 0.02),
                                flexion=(10.0, 0.005), pinned=[(0, 11), (11, 11)])
        if on:
            scene.set_self_collision(thickness=0.01)
        sim = tcloth.Simulator(scene, dt=2e-4)
        sim.step(700)
        runs.append(sim.positions())
        if on:
            assert sim.self_contacts() == {"point_triangle": 0, "edge_edge": 0}
    assert np.array_equal(*runs)
    assert np.ptp(runs[0][cloth.particles.ravel(), 1]) > 0.3      # it fell and swung


def crumpled(seed=0):
    """Two 3 x 3 cloths randomly placed within a thickness of each other."""
    rng = np.random.default_rng(seed)
    scene = tcloth.Scene(gravity=(0, 0, 0))
    for k in range(2):
        scene.add_cloth(resolution=(3, 3), size=(0.2, 0.2), center=(0, 0.01 * k, 0),
                        plane="xz", **CLOTH)
    x = scene.positions + rng.normal(scale=0.01, size=scene.positions.shape)
    return scene, x


def test_contact_energy_matches_a_numpy_brute_force(f64):
    scene, x = crumpled()
    scene.set_self_collision(thickness=0.03, stiffness=500.0)
    sim = tcloth.Simulator(scene)
    sim.set_state(positions=x)
    e = sim.energy()["self_contact"]
    assert e > 0
    np.testing.assert_allclose(e, numpy_energy(scene, x, 0.03, 500.0), rtol=1e-10)


@pytest.mark.slow
def test_contact_force_is_minus_the_energy_gradient(f64):
    scene, x = crumpled(1)
    forces = []
    for on in (False, True):
        if on:
            scene.set_self_collision(thickness=0.03, stiffness=500.0, damping=0.0)
        sim = tcloth.Simulator(scene)
        sim.set_state(positions=x)
        forces.append(sim.forces())
    contact = forces[1] - forces[0]
    grad = energy_gradient(sim, x, "self_contact", h=1e-7)
    assert np.abs(contact).max() > 1.0
    np.testing.assert_allclose(contact, -grad, atol=1e-5 * np.abs(contact).max())
    np.testing.assert_allclose(contact.sum(0), 0.0, atol=1e-10)


def test_bad_self_collision_input_names_the_argument():
    scene = tcloth.Scene()
    for kwargs, name in (({"thickness": 0.0}, "thickness"), ({"stiffness": -1.0}, "stiffness"),
                         ({"friction": -0.1}, "friction"), ({"skin": float("nan")}, "skin")):
        with pytest.raises(SceneError, match=name):
            scene.set_self_collision(**kwargs)
    scene.add_particles([[0, 0, 0]])
    scene.set_self_collision()
    with pytest.raises(SceneError, match="cloth or a rope"):
        tcloth.Simulator(scene)


@pytest.mark.slow
def test_folding_cloth_never_crosses_itself():
    """scenes/fold.py at 16 x 16 with its own integrator and dt: no cloth edge crosses a
    cloth triangle at any sampled frame while it folds onto itself (float32, the
    default). At 16 x 16 and one step per frame the cloth drapes over the rod without
    touching itself: tests/test_contact.py checks the implicit integrators at 1/60 s on
    cloths that do meet. The air damping is the scene's old drag of 2e-4 N s/m a particle
    at this resolution (0.256 1/s; the scene's 1.6 1/s is that drag at 40 x 40), with
    which the cloth reaches the rod and itself within the sampled second."""
    tcloth.init()
    scene = scene_module("fold").build(resolution=(16, 16), air_damping=0.256)
    topo = contact_topology(scene)
    sim = tcloth.Simulator(scene, "symplectic_euler", dt=2.5e-4)
    hits, contacts = [], []
    for _ in range(10):
        sim.step(400)
        hits.append(crossings(sim.positions().astype(np.float64), topo["edges"],
                              topo["triangles"]))
        contacts.append(sum(sim.self_contacts().values()))
    assert max(contacts) > 10, contacts
    assert hits == [0] * 10


@pytest.mark.slow
def test_checkpoint_with_self_collision_continues_the_run(tmp_path):
    """Saved while two cloths touch, a checkpoint continues bit for bit: it keeps where the
    proximity list was built, and the loaded simulator rebuilds the same list there."""
    tcloth.init()
    scene, _, x, v = colliding_cloths(res=6)
    scene.set_self_collision(thickness=0.02)
    sim = tcloth.Simulator(scene, dt=1e-4)
    sim.set_state(positions=x, velocities=v)
    sim.step(550)
    assert sum(sim.self_contacts().values()) > 0
    sim.save(tmp_path / "touching.npz")
    loaded = tcloth.Simulator.load(tmp_path / "touching.npz")
    assert loaded.scene.self_collision == sim.scene.self_collision
    assert loaded.self_contacts() == sim.self_contacts()
    sim.step(100)
    loaded.step(100)
    assert np.array_equal(loaded.positions(), sim.positions())


@pytest.mark.slow
def test_kept_candidate_list_misses_no_contact(f64):
    """Between rebuilds the contact stage's list is reused while no two particles can have
    moved relative to each other by more than the skin. While a cloth folds onto itself,
    the forces from the kept list equal, every 20 steps, those from a list rebuilt at that
    state."""
    sim = tcloth.Simulator(scene_module("fold").build(resolution=(12, 12)), dt=2.5e-4)
    broad = sim.contact.broad
    sim.step(2800)
    stepping_rebuilds, contacts = 0, []
    for _ in range(40):
        before = broad.rebuilds
        sim.step(20)
        stepping_rebuilds += broad.rebuilds - before
        kept = sim.forces()
        sim.contact.refresh(sim.state.x)          # a fresh list at this state
        fresh = sim.forces()
        contacts.append(sum(sim.self_contacts().values()))
        np.testing.assert_allclose(kept, fresh, rtol=0, atol=1e-12 * np.abs(fresh).max())
    assert max(contacts) > 10, contacts
    assert stepping_rebuilds < 0.5 * 800, stepping_rebuilds


def pairs_within(x, table, reach):
    """Every point-triangle and edge-edge pair sharing no particle whose distance at x is
    within ``reach``, by brute force (boxes first), as ``pair_key``s."""
    points, triangles, edges = (getattr(table, k).to_numpy() for k in
                                ("points", "triangles", "edges"))
    found = set()
    lo, hi = x[triangles].min(axis=1) - reach, x[triangles].max(axis=1) + reach
    for p in points:
        for t in np.flatnonzero(((lo <= x[p]) & (x[p] <= hi)).all(axis=1)):
            if p not in triangles[t] and point_triangle(x[p], *x[triangles[t]]) <= reach:
                found.add(pair_key([p, *triangles[t]], 0))
    lo, hi = x[edges].min(axis=1), x[edges].max(axis=1)
    for i, e in enumerate(edges):
        near = ((lo[i] <= hi + reach) & (lo <= hi[i] + reach)).all(axis=1)
        for j in np.flatnonzero(near[i + 1:]) + i + 1:
            if not set(e) & set(edges[j]) and segment_segment(*x[e], *x[edges[j]]) <= reach:
                found.add(pair_key([*e, *edges[j]], 1))
    return found


def pair_key(ids, kind):
    """A contact's particles without their order within a side, nor the edges' order."""
    ids = [int(i) for i in ids]
    if kind == 0:
        return 0, ids[0], tuple(sorted(ids[1:]))
    return (1,) + tuple(sorted([tuple(sorted(ids[:2])), tuple(sorted(ids[2:]))]))


def test_the_list_holds_each_pair_within_reach_once_and_skips_only_far_rows(f64):
    """The proximity list holds each pair within thickness + skin once, as a NumPy brute
    force finds them (the edge queries look for each pair from one side only:
    ``PointGrid.for_each_partner``). A consumer of the list skips a row whose gap at the
    build less the largest displacements of a particle of each side from the
    displacements' centre (``broad.near``) is beyond the thickness. Against NumPy's
    distances: the gaps kept at the build are the rows' gaps there, and after motions of
    up to twice the skin (some particles still, some moving far) every skipped row is
    beyond the thickness at both ends of the motion and halfway, while the bound skips a
    third of the rows at a tenth of the skin."""
    import taichi as ti
    from tcloth.contact import broad as broad_phase

    @ti.kernel
    def near_rows(cl: ti.template(), count: ti.i32, ref_gap: ti.template(),
                  far: ti.template(), distance: float, out: ti.types.ndarray()):
        for c in range(count):
            out[c] = int(broad_phase.near(cl, ref_gap, far, c, distance))

    def gaps(x, ids, kinds):
        return np.array([point_triangle(x[i[0]], *x[i[1:]]) if k == 0 else
                         segment_segment(*x[i]) for i, k in zip(ids, kinds)])

    rng = np.random.default_rng(7)
    scene = tcloth.Scene(gravity=(0, 0, 0))
    for k in range(3):
        scene.add_cloth(resolution=(6, 6), size=(0.3, 0.3), center=(0, 0.02 * k, 0),
                        plane="xz", **CLOTH)
    thickness = skin = 0.015
    scene.set_self_collision(thickness=thickness, skin=skin)
    x_ref = scene.positions + rng.normal(scale=0.004, size=scene.positions.shape)
    sim = tcloth.Simulator(scene)
    sim.set_state(positions=x_ref)
    broad = sim.contact.broad
    cl, count = broad.candidates, broad.count
    ids, kinds = cl.ids.to_numpy()[:count], cl.kind.to_numpy()[:count]
    listed = [pair_key(i, k) for i, k in zip(ids, kinds)]
    expected = pairs_within(x_ref, broad.table, thickness + skin)
    assert len(set(listed)) == len(listed) and set(listed) == expected
    assert sum(k for k, *_ in expected) > 100, "edge-edge pairs"
    np.testing.assert_allclose(broad.ref_gap.to_numpy()[:count], gaps(x_ref, ids, kinds),
                               rtol=1e-10)
    ends = [sim.model.state() for _ in range(2)]
    skipped = []
    for trial, scale in enumerate((0.1, 0.3, 1.0, 2.0)):
        still = rng.random(len(x_ref)) < 0.5
        motions = [np.where(still[:, None], 0.0,
                            rng.uniform(-1, 1, x_ref.shape) * scale * skin / np.sqrt(3))
                   for _ in range(2)]
        ys = [x_ref + 0.3 * trial + m for m in motions]        # a shared motion costs none
        for end, y in zip(ends, ys):
            end.x.from_numpy(y)
        broad.moved(ends[0].x, ends[1].x)
        out = np.zeros(count, dtype=np.int32)
        near_rows(cl, count, broad.ref_gap, broad.far, thickness, out)
        far_rows = out == 0
        for y in (ys[0], ys[1], 0.5 * (ys[0] + ys[1])):
            assert (gaps(y, ids[far_rows], kinds[far_rows]) > thickness).all()
        skipped.append(int(far_rows.sum()))
    assert skipped[0] > 0.3 * count and skipped[-1] < skipped[0], (skipped, count)


@pytest.mark.slow
def test_displacement_test_matches_numpy_on_one_thread_and_on_several():
    """The rebuild test's reduction (blocks of particles, then the blocks) gives what NumPy
    gives from the positions: twice the largest distance of a displacement since the last
    build from the middle of the displacements' bounding box, of one state or of two (a
    step's start and end); the same on one thread and with every loop parallel, over
    several blocks."""
    from tcloth.contact import broad as broad_phase
    noise = 1e-3 * np.random.default_rng(5).standard_normal((3, 1600, 3))
    results = []
    try:
        for serial_below in (tcloth.runtime.SERIAL_BELOW, 0):
            tcloth.init(arch="cpu", precision="f64", serial_below=serial_below)
            scene = tcloth.Scene()
            scene.add_cloth(resolution=(40, 40), **CLOTH)
            scene.set_self_collision(thickness=0.005)
            sim = tcloth.Simulator(scene, dt=1e-3)
            broad = sim.contact.broad
            x_ref = sim.positions()
            other = sim.model.state()
            assert len(x_ref) > 1.5 * broad_phase.DISPLACEMENT_BLOCK
            previous = None
            for shift, jitter in zip((0.0, 0.3, -0.2), noise):
                x = x_ref + shift + jitter
                other.x.from_numpy(x)
                ds = [x - x_ref] + ([] if previous is None else [previous - x_ref])
                both = np.concatenate(ds)
                centre = 0.5 * (both.min(axis=0) + both.max(axis=0))
                expected = 2 * np.linalg.norm(both - centre, axis=1).max()
                if previous is None:
                    got = broad_phase._spread(broad, broad.x_ref, other.x, other.x, False)
                else:
                    prev = sim.model.state()
                    prev.x.from_numpy(previous)
                    got = broad_phase._spread(broad, broad.x_ref, other.x, prev.x, True)
                assert got == pytest.approx(expected, rel=1e-12)
                np.testing.assert_allclose(broad.centre.to_numpy(), centre, rtol=0,
                                           atol=1e-15)
                each = np.linalg.norm(np.stack(ds) - centre, axis=2).max(axis=0)
                np.testing.assert_allclose(broad.far.to_numpy(), each, rtol=1e-12)
                results.append(got)
                previous = x
    finally:
        tcloth.init(arch="cpu", precision="f64", serial_below=tcloth.runtime.SERIAL_BELOW)
    assert results[:3] == results[3:]
