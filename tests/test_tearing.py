"""Tearing (``Scene.set_tearing``, ``sim/tearing.py``): springs that break at their strain,
against closed forms (a hanging chain's tension), conservation (no energy made, linear
momentum kept) and the torn cloth's topology (NumPy)."""
import numpy as np
import pytest

import tcloth
from tcloth.sim.tearing import holding_triangles

from test_simulator import launches

SOLVERS = ["symplectic_euler", "verlet", "xpbd", "vbd", "projective", "backward_euler"]


def hanging_chain(g0, max_strain=0.2, n=5, l0=0.1, k=200.0, m=0.05, weight=0.2):
    """(scene, the free mass) of a chain of n particles hanging from a pinned top at its
    static equilibrium under gravity g0 (m/s^2): spring s holds the weight below it,
    so it is l0 + g0 (mass below) / k long."""
    scene = tcloth.Scene(gravity=(0.0, -g0, 0.0))
    mass = np.full(n, m)
    mass[-1] = weight
    below = np.cumsum(mass[::-1])[::-1][1:]
    x = np.zeros((n, 3))
    x[1:, 1] = -np.cumsum(l0 + g0 * below / k)
    ids = scene.add_particles(x, mass=mass, pinned=np.arange(n) == 0)
    scene.add_springs(np.stack([ids[:-1], ids[1:]], 1), k, damping=10.0, rest_length=l0)
    scene.set_tearing(max_strain=max_strain)
    return scene, float(below[0])


def ramp(sim, g0, rate, steps):
    """Gravity g0 + rate t (m/s^2, t from now) for up to ``steps`` steps, stopping after the
    first that breaks a spring; (the gravity of that step or None, the positions before
    it)."""
    for s in range(steps):
        g = g0 + rate * s * sim.dt
        sim.set_gravity((0.0, -g, 0.0))
        before = sim.positions()
        sim.step()
        if len(sim.torn()):
            return g, before
    return None, sim.positions()


def test_a_hanging_chain_tears_at_its_top_when_the_weight_reaches_k_strain_l0(f64):
    k, l0, eps = 200.0, 0.1, 0.2
    scene, free = hanging_chain(9.0, eps, k=k, l0=l0)
    sim = tcloth.Simulator(scene, dt=2e-3)
    g, before = ramp(sim, 9.0, 4.0, 1000)
    # quasi-static: the top spring holds the whole free weight, g m = k eps l0 at the break
    assert g is not None
    assert g * free == pytest.approx(k * eps * l0, rel=0.02)
    assert list(sim.torn()) == [0]                           # the top spring, alone
    # not before: the step before the break left the top spring below its strain
    assert np.linalg.norm(before[1] - before[0]) <= (1 + eps) * l0
    sim.step(150)                                            # the rest falls, unstrained
    assert list(sim.torn()) == [0]
    assert sim.positions()[1:, 1].max() < before[1:, 1].min()


def test_below_the_threshold_nothing_breaks(f64):
    k, l0, eps = 200.0, 0.1, 0.2
    scene, free = hanging_chain(9.0, eps, k=k, l0=l0)
    sim = tcloth.Simulator(scene, dt=2e-3)
    g_max = 0.97 * k * eps * l0 / free
    g, _ = ramp(sim, 9.0, 4.0, int((g_max - 9.0) / 4.0 / 2e-3))
    assert g is None
    sim.step(500)
    assert len(sim.torn()) == 0
    top = np.linalg.norm(np.diff(sim.positions()[:2], axis=0))
    assert top == pytest.approx(l0 * (1 + 0.97 * eps), rel=0.01)   # the static stretch


def flying_apart(max_strain=0.3, n=6, l0=0.1, k=500.0):
    """A free chain along x whose particles fly apart (uniform expansion) and drift, with
    no gravity: every spring stretches until the first tears."""
    scene = tcloth.Scene(gravity=(0.0, 0.0, 0.0))
    x = np.zeros((n, 3))
    x[:, 0] = l0 * np.arange(n)
    rng = np.random.default_rng(3)
    mass = rng.uniform(0.01, 0.03, n)
    v = np.zeros((n, 3))
    v[:, 0] = 100.0 * (x[:, 0] - x[:, 0].mean())
    v += (0.3, -0.2, 0.1)
    ids = scene.add_particles(x, mass=mass, velocities=v)
    scene.add_springs(np.stack([ids[:-1], ids[1:]], 1), k, rest_length=l0)
    scene.set_tearing(max_strain=max_strain)
    return scene, mass


def numpy_energy(scene, x, v, mass, intact):
    """Kinetic plus elastic energy of the springs in ``intact`` (NumPy)."""
    sp = scene.springs
    pairs = sp["pairs"][intact]
    length = np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1)
    elastic = 0.5 * sp["stiffness"][intact] * (length - sp["rest_length"][intact]) ** 2
    return 0.5 * float((mass * (v ** 2).sum(1)).sum()) + float(elastic.sum())


@pytest.mark.parametrize("integrator", SOLVERS)
def test_a_tear_makes_no_energy_and_keeps_linear_momentum(f64, integrator):
    scene, mass = flying_apart()
    dt = 2e-4 if integrator in ("symplectic_euler", "verlet") else 2e-3
    sim = tcloth.Simulator(scene, integrator, dt=dt)
    p0 = (mass[:, None] * scene.velocities).sum(0)
    everything = np.arange(scene.num_springs)
    for _ in range(int(0.5 / dt)):
        x, v = sim.positions(), sim.velocities()
        before = numpy_energy(scene, x, v, mass, everything)
        sim.step()
        if len(sim.torn()):
            break
    torn = sim.torn()
    assert len(torn) >= 1
    intact = np.setdiff1d(everything, torn)
    x1, v1 = sim.positions(), sim.velocities()
    after = numpy_energy(scene, x1, v1, mass, intact)
    assert after <= before * (1 + 1e-6)
    # the simulator's own sum leaves the broken spring out too
    assert sim.energy()["total"] == pytest.approx(after, rel=1e-6)
    if integrator == "vbd":
        return        # VBD's Gauss-Seidel sweeps move momentum by their residual, torn or not
    np.testing.assert_allclose((mass[:, None] * v1).sum(0), p0, rtol=0, atol=1e-7)
    sim.step(50)
    np.testing.assert_allclose((mass[:, None] * sim.velocities()).sum(0), p0, rtol=0,
                               atol=1e-7)


def test_families_choose_which_springs_tear_and_bad_input_is_refused(f64):
    scene = tcloth.Scene(gravity=(0.0, 0.0, 0.0))
    ids = scene.add_particles([[0, 0, 0], [0.1, 0, 0], [0.2, 0, 0]], mass=0.01,
                              velocities=[[-3, 0, 0], [0, 0, 0], [3, 0, 0]])
    scene.add_springs([[ids[0], ids[1]]], 100.0, rest_length=0.1, kind="structural")
    scene.add_springs([[ids[1], ids[2]]], 100.0, rest_length=0.1, kind="shear")
    scene.set_tearing(max_strain=0.1, families=("shear",))
    sim = tcloth.Simulator(scene, dt=1e-4)
    strain = []
    for _ in range(300):
        sim.step()
        strain.append(sim.max_strain())
    assert list(sim.torn()) == [1]
    assert max(strain) > 0.15              # the structural one stretches on, unbroken
    for bad in (dict(max_strain=0.0), dict(max_strain=-1), dict(families=("warp",)),
                dict(families=())):
        with pytest.raises(tcloth.SceneError, match="max_strain|families"):
            scene.set_tearing(**bad)


def test_tearing_launches_nothing_where_it_is_off_and_one_kernel_where_it_is_on(
        f64, monkeypatch):
    off, _ = flying_apart()
    off.tearing = None
    names = launches(monkeypatch, tcloth.Simulator(off, dt=1e-4, batch=False), 3)
    assert "_tear" not in names
    on, _ = flying_apart()
    names_on = launches(monkeypatch, tcloth.Simulator(on, dt=1e-4, batch=False), 3)
    assert names_on.count("_tear") == 3
    assert [n for n in names_on if n != "_tear"] == names


def grid_pulled_apart(n=8, speed=0.5, **options):
    """A simulator of an n x n cloth in the xz plane, without gravity, whose first and
    last columns are pinned and move apart along x at ``speed`` (m/s) each."""
    scene = tcloth.Scene(gravity=(0.0, 0.0, 0.0))
    edges = [(i, j) for i in (0, n - 1) for j in range(n)]
    scene.add_cloth(resolution=(n, n), size=(0.7, 0.7), center=(0, 0, 0), plane="xz",
                    mass=0.1, structural=(200.0, 0.5), shear=(50.0, 0.1), flexion=None,
                    pinned=edges)
    scene.set_tearing(max_strain=0.3)
    sim = tcloth.Simulator(scene, **options)
    v = np.zeros((scene.num_particles, 3))
    v[scene.pinned, 0] = np.sign(scene.positions[scene.pinned, 0]) * speed
    sim.set_state(velocities=v)
    return sim


EDGES = ((0, 1), (1, 2), (2, 0))


def edge_map(triangles):
    """{(a, b) with a < b: the triangles with that edge}."""
    edges = {}
    for t, tri in enumerate(triangles):
        for a, b in EDGES:
            edges.setdefault(tuple(sorted((tri[a], tri[b]))), []).append(t)
    return edges


def surface_pieces(triangles):
    """(the roots of the connected pieces of a triangle list (triangles joined by a
    shared edge), its ``edge_map``)."""
    edges = edge_map(triangles)
    parent = list(range(len(triangles)))

    def root(t):
        while parent[t] != t:
            parent[t] = parent[parent[t]]
            t = parent[t]
        return t
    for shared in edges.values():
        for t in shared[1:]:
            parent[root(t)] = root(shared[0])
    return {root(t) for t in range(len(triangles))}, edges


def test_a_cloth_pulled_apart_separates_into_consistent_pieces(f64, tmp_path):
    sim = grid_pulled_apart(dt=2e-4)
    scene = sim.scene
    for _ in range(30):
        sim.step(100)
        if len(surface_pieces(scene.triangles[sim.surface()])[0]) > 1:
            break
    torn = sim.torn()
    x = sim.positions()
    held = sim.surface()
    np.testing.assert_array_equal(held, holding_triangles(scene, torn))
    kept = scene.triangles[held]
    # every kept triangle: three distinct particles, no broken spring along an edge
    assert np.all(np.diff(np.sort(kept, axis=1), axis=1) > 0)
    pairs = {tuple(sorted(p)) for p in scene.springs["pairs"][torn]}
    assert not any(tuple(sorted((t[a], t[b]))) in pairs
                   for t in kept for a, b in EDGES)
    # pieces, the two pinned edges in different ones, each edge in one or two triangles
    pieces, edges = surface_pieces(kept)
    assert len(pieces) >= 2
    assert all(1 <= len(ts) <= 2 for ts in edges.values())
    ids = scene.cloths[0].particles
    piece_of = {}
    for k, tri in enumerate(kept):
        for p in tri:
            piece_of.setdefault(p, set()).add(k)
    left = {t for p in ids[:, 0] for t in piece_of.get(p, ())}
    right = {t for p in ids[:, -1] for t in piece_of.get(p, ())}
    assert left and right and not (_joined(kept, edges, left) & _joined(kept, edges, right))
    # the exported mesh is the kept triangles
    path = tmp_path / "torn.obj"
    tcloth.export_mesh(sim, str(path))
    vertices, faces = tcloth.load_obj(str(path))
    assert len(faces) == len(kept)
    np.testing.assert_allclose(vertices[np.asarray(faces)], x[kept], atol=1e-12)


def _joined(triangles, edges, start):
    """The triangles joined to those of ``start`` by shared edges (``edge_map``)."""
    seen, todo = set(start), list(start)
    while todo:
        tri = triangles[todo.pop()]
        for a, b in EDGES:
            for t in edges[tuple(sorted((tri[a], tri[b])))]:
                if t not in seen:
                    seen.add(t)
                    todo.append(t)
    return seen


def test_a_checkpoint_keeps_what_broke_and_reset_mends_it(f64, tmp_path):
    sim = grid_pulled_apart(6, dt=2e-4)
    sim.step(1100)
    torn = sim.torn()
    assert len(torn)
    path = str(tmp_path / "torn.npz")
    sim.save(path)
    again = tcloth.Simulator.load(path)
    np.testing.assert_array_equal(again.torn(), torn)
    sim.step(200)
    again.step(200)
    np.testing.assert_array_equal(again.positions(), sim.positions())
    np.testing.assert_array_equal(again.torn(), sim.torn())
    sim.reset()
    assert len(sim.torn()) == 0 and sim.surface().all()
    assert sim.energy()["spring"] == pytest.approx(0.0, abs=1e-12)


def test_the_wind_blows_on_the_triangles_that_hold(f64):
    """Wind drag (Wejchert & Haumann, no lift) on a torn cloth: NumPy's over the held
    triangles only, added to the intact springs'."""
    scene = grid_pulled_apart(8).scene
    scene.set_wind(velocity=(0.5, 2.0, 0.0), drag=0.4)
    sim = tcloth.Simulator(scene, dt=2e-4)
    v = np.zeros((scene.num_particles, 3))
    v[scene.pinned, 0] = np.sign(scene.positions[scene.pinned, 0]) * 0.5
    sim.set_state(velocities=v)
    assert sim.fusion() is not None             # the wind follows a tear from Python
    run_until_torn(sim)
    x, v = sim.positions(), sim.velocities()
    intact = np.setdiff1d(np.arange(scene.num_springs), sim.torn())
    expected = numpy_forces(scene, x, v, intact)
    for a, b, c in scene.triangles[sim.surface()]:
        cross = np.cross(x[b] - x[a], x[c] - x[a])
        n = cross / np.linalg.norm(cross)
        u = (np.array([0.5, 2.0, 0.0]) - (v[a] + v[b] + v[c]) / 3.0) @ n
        expected[[a, b, c]] += 0.5 * np.linalg.norm(cross) * 0.4 * u * abs(u) * n / 3.0
    free = ~scene.pinned
    np.testing.assert_allclose(sim.forces()[free], expected[free], rtol=1e-9, atol=1e-9)


@pytest.mark.slow_cases("projective")
@pytest.mark.parametrize("integrator", ["symplectic_euler", "projective"])
def test_a_hinge_across_a_tear_bends_no_more(f64, integrator):
    """Hinge bending (c = sqrt(B/A) K a hinge, energy |sum c_i x_i|^2 / 2) on a torn cloth:
    the sum over the hinges whose two triangles hold (NumPy, from the springs that broke),
    with the untorn cloth's weights."""
    scene = grid_pulled_apart(8).scene
    scene.set_bending(2e-4)
    sim = tcloth.Simulator(scene, integrator, dt=2e-4 if integrator != "projective" else 1e-3)
    weights = sim.model.bending.weights.to_numpy()
    v = np.zeros((scene.num_particles, 3))
    v[scene.pinned, 0] = np.sign(scene.positions[scene.pinned, 0]) * 0.5
    sim.set_state(velocities=v)
    run_until_torn(sim, chunk=20 if integrator == "projective" else 100)
    hinges = sim.model.bending.ids
    cut = {tuple(sorted(p)) for p in scene.springs["pairs"][sim.torn()]}
    held = np.array([not any(tuple(sorted((h[a], h[b]))) in cut
                             for a, b in ((0, 1), (0, 2), (1, 2), (0, 3), (1, 3)))
                     for h in hinges])
    assert 0 < held.sum() < len(hinges)
    x = sim.positions()
    s = np.einsum("hk,hkd->hd", weights, x[hinges])
    assert sim.energy()["bending"] == pytest.approx(0.5 * (s[held] ** 2).sum(), rel=1e-9)


def test_features_that_a_tear_does_not_cut_are_refused(f64):
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(4, 4))
    scene.set_tearing()
    scene.set_membrane(100.0, 10.0)
    with pytest.raises(tcloth.SceneError, match="tearing does not cut the membrane"):
        tcloth.Simulator(scene)


def run_until_torn(sim, chunk=100, most=30):
    """Step ``sim`` in chunks until a cloth triangle is torn (at most ``most`` chunks)."""
    for _ in range(most):
        sim.step(chunk)
        if not sim.surface().all():
            return
    raise AssertionError("nothing tore")


def test_the_renderer_draws_only_the_triangles_that_hold(f32):
    from tcloth.render.render import renderer_for
    sim = grid_pulled_apart(6, dt=2e-4)
    camera = {"eye": (0.0, 1.5, 0.01), "target": (0.0, 0.0, 0.0)}
    renderer = renderer_for(sim, 96, 72, camera=camera, shadows=False)
    renderer.render()
    assert len(np.unique(renderer.ids()[renderer.ids() < renderer.tri_count])) > 40
    run_until_torn(sim)
    sim.step(300)
    image = renderer.render()
    assert np.isfinite(image).all()
    ids = renderer.ids()
    drawn = np.unique(ids[ids < renderer.tri_count])
    kept = {tuple(sorted(t)) for t in sim.scene.triangles[sim.surface()]}
    corners = renderer.corners.to_numpy()[drawn]
    assert len(drawn) and all(tuple(sorted(c)) in kept for c in corners)


def test_usd_export_follows_the_tear_frame_by_frame(f32, tmp_path):
    pytest.importorskip("pxr", reason="usd-core (pxr) is not installed")
    from pxr import Usd, UsdGeom, UsdValidation
    sim = grid_pulled_apart(6, dt=2e-4)
    path = str(tmp_path / "torn.usda")
    writer = tcloth.UsdWriter(sim, path, fps=24)
    held = []
    for frame in range(8):
        if frame:
            sim.step(200)
        writer.write()
        held.append(sim.surface().copy())
    writer.close()
    assert held[0].all() and not held[-1].all()
    stage = Usd.Stage.Open(path)
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Cloths/cloth_0"))
    local = sim.scene.cloths[0].triangles - sim.scene.cloths[0].offset
    for frame, keep in enumerate(held):
        indices = np.array(mesh.GetFaceVertexIndicesAttr().Get(frame)).reshape(-1, 3)
        np.testing.assert_array_equal(indices, local[keep])
        assert list(mesh.GetFaceVertexCountsAttr().Get(frame)) == [3] * int(keep.sum())
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    errors = UsdValidation.ValidationContext(validators).Validate(stage)
    assert not [(e.GetName(), e.GetMessage()) for e in errors]


@pytest.mark.parametrize("pull, tears", [(0.03, False), (0.8, True)])
def test_dragging_a_cloth_hard_in_the_viewer_tears_it(f32, pull, tears):
    """The sandbox's drag (``viewer.controls``, no window needed): the particle under the
    cursor pulled ``pull`` m down by the grab spring; hard, the cloth tears around it,
    gently, nothing breaks."""
    from tcloth.render.camera import Camera
    from tcloth.viewer.camera import OrbitCamera
    from tcloth.viewer.controls import Controls
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0), air_damping=1.0)
    scene.add_cloth(resolution=(10, 10), size=(0.5, 0.5), center=(0.0, 1.0, 0.0),
                    plane="xy", mass=0.05, structural=(200.0, 0.05), shear=(40.0, 0.02),
                    flexion=None, pinned=[(i, 0) for i in range(10)])
    scene.set_tearing(max_strain=0.5)
    sim = tcloth.Simulator(scene, dt=2.5e-4, grab=True)
    sim.step(400)
    controls = Controls(sim, substeps=100)
    camera = OrbitCamera(Camera((0.0, 1.0, 2.0), (0.0, 1.0, 0.0), fov=40.0))
    particle = controls.start_drag(camera, 0.5, 0.5, 1.0)
    assert particle is not None
    depth = float((sim.positions()[particle] - camera.eye) @ camera.basis[0])
    below = 0.5 - pull / (2 * depth * np.tan(np.radians(20.0)))
    for _ in range(20):
        controls.drag(camera, 0.5, below, 1.0)
        controls.advance()
    assert not controls.message
    assert (len(sim.torn()) > 0) == tears
    if tears:          # the springs at the dragged particle broke first
        assert particle in scene.springs["pairs"][sim.torn()[:4]]


def numpy_forces(scene, x, v, intact):
    """Gravity, air damping and the forces of the springs ``intact`` (NumPy)."""
    sp = scene.springs
    f = scene.masses[:, None] * np.asarray(scene.gravity)[None, :] \
        - scene.drag_coefficients()[:, None] * v
    pairs = sp["pairs"][intact]
    d = x[pairs[:, 0]] - x[pairs[:, 1]]
    length = np.linalg.norm(d, axis=1)
    rate = ((v[pairs[:, 0]] - v[pairs[:, 1]]) * d).sum(1) / length
    fi = -((sp["stiffness"][intact] * (length - sp["rest_length"][intact])
            + sp["damping"][intact] * rate) / length)[:, None] * d
    np.add.at(f, pairs[:, 0], fi)
    np.add.at(f, pairs[:, 1], -fi)
    return f


@pytest.mark.parametrize("grid_stencil", [True, False])
def test_a_torn_cloths_forces_are_its_intact_springs(f64, grid_stencil):
    """The stencil (a flag per slot) and the spring list (k_s = k_d = 0) both leave the
    broken springs out: the forces are NumPy's over the springs that hold."""
    sim = grid_pulled_apart(8, dt=2e-4, grid_stencil=grid_stencil)
    assert bool(sim.model.grids) == grid_stencil
    run_until_torn(sim)
    intact = np.setdiff1d(np.arange(sim.scene.num_springs), sim.torn())
    expected = numpy_forces(sim.scene, sim.positions(), sim.velocities(), intact)
    free = ~sim.scene.pinned
    np.testing.assert_allclose(sim.forces()[free], expected[free], rtol=1e-9, atol=1e-9)


@pytest.mark.slow_cases("verlet")
@pytest.mark.parametrize("integrator", ["symplectic_euler", "verlet"])
def test_a_batch_tears_as_single_steps_do_bit_for_bit(f64, integrator):
    """Batches (``sim/batch.py``) break springs inside their kernel: the same springs at
    the same steps and the same states as steps launched one by one."""
    runs = []
    for batch in (True, False):
        sim = grid_pulled_apart(6, dt=2e-4, batch=batch, integrator=integrator)
        assert (sim.fusion() is None) == batch
        sim.step(1400)
        runs.append((sim.positions(), sim.torn(), sim.surface()))
    assert len(runs[0][1])
    for a, b in zip(*runs):
        np.testing.assert_array_equal(a, b)


def test_a_batch_taken_again_from_its_start_mends_what_broke_in_it(f64, monkeypatch):
    """A batch whose end fails the stored-energy check runs its steps again one at a time
    from its start (``Batches.run``): the springs that broke in the first pass hold again
    there, so the steps repeat the same numbers."""
    runs = []
    for fail_once in (False, True):
        sim = grid_pulled_apart(6, dt=2e-4)
        sim.step(1000)
        assert sim.fusion() is None and not len(sim.torn())
        if fail_once:
            verify, calls = sim._checker.verify, []

            def verify_failing_first(*args):
                calls.append(args)
                return "bad" if len(calls) == 1 else verify(*args)
            monkeypatch.setattr(sim._checker, "verify", verify_failing_first)
        sim.step(400)
        assert not fail_once or len(calls) > 400         # taken again, step by step
        runs.append((sim.positions(), sim.torn()))
    assert len(runs[0][1])
    for a, b in zip(*runs):
        np.testing.assert_array_equal(a, b)


def test_the_strain_limit_leaves_a_broken_spring_alone(f64):
    """Provot's limit (10 %) on springs that tear at 5 %: once broken, a spring's ends go
    apart past the limit (the limiter no longer shortens it); those that hold stay
    within it."""
    scene = tcloth.Scene(gravity=(0.0, 0.0, 0.0))
    ids = scene.add_particles([[0, 0, 0], [0.1, 0, 0], [0.2, 0, 0]], mass=0.01,
                              velocities=[[-2, 0, 0], [0, 0, 0], [0, 0, 0]])
    scene.add_springs([[ids[0], ids[1]], [ids[1], ids[2]]], 100.0, rest_length=0.1)
    scene.limit_strain(max_stretch=0.1, kinds=("custom",))
    scene.set_tearing(max_strain=0.05)
    sim = tcloth.Simulator(scene, dt=1e-4)
    sim.step(400)
    assert list(sim.torn()) == [0]
    x = sim.positions()
    assert np.linalg.norm(x[1] - x[0]) > 0.15                 # far past 1.1 rest lengths
    assert np.linalg.norm(x[2] - x[1]) <= 0.11 * (1 + 1e-9)
    assert sim.max_strain() <= 0.1 + 1e-9                     # the broken one left out
