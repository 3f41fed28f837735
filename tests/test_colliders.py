"""Colliders: penalty contact and Coulomb friction against closed forms and bounds."""
import numpy as np
import pytest
import taichi as ti

import tcloth
from tcloth.model.collider_table import ColliderTable
from tcloth.geometry.shapes import SHAPES
from tcloth.terms.colliders import Colliders
from tcloth import SceneError

G = 9.81


def incline(theta_deg, mu, m=0.1, k=2000.0, thickness=0.01):
    """A particle resting on a plane through the origin tilted by theta about z."""
    th = np.radians(theta_deg)
    n = np.array([-np.sin(th), np.cos(th), 0.0])
    scene = tcloth.Scene(gravity=(0, -G, 0))
    rest = (thickness - m * G * np.cos(th) / k) * n
    scene.add_particles([rest], mass=m)
    scene.add_plane((0, 0, 0), n, friction=mu, thickness=thickness, stiffness=k)
    return scene, np.array([np.cos(th), np.sin(th), 0.0])


def test_particle_rests_at_thickness_within_penalty_deflection(f64):
    m, k, thick = 0.1, 1000.0, 0.01
    scene = tcloth.Scene(gravity=(0, -G, 0))
    scene.add_particles([[0.3, 0.2, -0.1]], mass=m)
    scene.add_plane((0, 0, 0), (0, 1, 0), thickness=thick, stiffness=k)
    sim = tcloth.Simulator(scene, "symplectic_euler", dt=2e-4)
    sim.step(10_000)
    deflection = m * G / k
    y = sim.positions()[0, 1]
    assert abs(y - (thick - deflection)) < 1e-3 * deflection
    assert np.linalg.norm(sim.velocities()) < 1e-6
    assert np.isclose(sim.energy()["contact"], 0.5 * k * deflection ** 2, rtol=1e-3)


@pytest.mark.parametrize("theta,mu", [(30.0, 0.2), (45.0, 0.5), (20.0, 0.0)])
def test_sliding_down_incline_accelerates_at_coulomb_rate(f64, theta, mu):
    scene, down = incline(theta, mu)
    sim = tcloth.Simulator(scene, "symplectic_euler", dt=1e-4)
    x0 = sim.positions()[0]
    sim.step(5000)
    t = sim.time
    along = -(sim.positions()[0] - x0) @ down
    a_measured = 2 * along / t ** 2
    a_expected = G * (np.sin(np.radians(theta)) - mu * np.cos(np.radians(theta)))
    assert abs(a_measured / a_expected - 1) < 0.03


def test_static_friction_holds_on_10_degree_incline(f64):
    scene, down = incline(10.0, 0.5)
    sim = tcloth.Simulator(scene, "symplectic_euler", dt=1e-4)
    sim.step(2000)
    x1 = sim.positions()[0]
    sim.step(10_000)
    creep = np.linalg.norm(sim.positions()[0] - x1) / (10_000 * 1e-4)
    assert creep < 2e-3
    # the regularised stick regime creeps at eps tan(theta) / mu (module docstring)
    assert creep == pytest.approx(1e-3 * np.tan(np.radians(10.0)) / 0.5, rel=0.05)


def box_rotation(seed=0):
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def numpy_sdf(collider, x):
    """Independent signed distance and normal for every shape."""
    c = collider["center"]
    if collider["kind"] == "capsule":
        q = collider["rotation"].T @ (x - c)
        d = q - [0.0, np.clip(q[1], -collider["half_height"], collider["half_height"]), 0.0]
        return np.linalg.norm(d) - collider["radius"], collider["rotation"] @ (
            d / np.linalg.norm(d))
    if collider["kind"] == "sphere":
        d = x - c
        return np.linalg.norm(d) - collider["radius"], d / np.linalg.norm(d)
    if collider["kind"] == "plane":
        n = collider["normal"]
        return (x - c) @ n, n
    if collider["kind"] == "cylinder":
        r = collider["rotation"]
        q = r.T @ (x - c)
        axis = np.array([0.0, np.sign(q[1]) or 1.0, 0.0])
        rho = np.hypot(q[0], q[2])
        out = np.array([q[0], 0.0, q[2]]) / rho
        side, cap = rho - collider["radius"], abs(q[1]) - collider["half_height"]
        if side > 0 or cap > 0:
            a, b = max(side, 0.0), max(cap, 0.0)
            return np.hypot(a, b), r @ ((a * out + b * axis) / np.hypot(a, b))
        return (cap, r @ axis) if cap > side else (side, r @ out)
    r, h = collider["rotation"], collider["half_extents"]
    q = r.T @ (x - c)
    d = np.abs(q) - h
    if (d > 0).any():
        o = np.maximum(d, 0)
        return np.linalg.norm(o), r @ (o / np.linalg.norm(o) * np.sign(q))
    axis = int(np.argmax(d))
    nl = np.zeros(3)
    nl[axis] = np.sign(q[axis])
    return d[axis], r @ nl


@pytest.mark.parametrize("kind", ["sphere", "plane", "box", "cylinder", "capsule"])
def test_friction_bounded_by_mu_normal_and_never_accelerates(f64, kind):
    rng = np.random.default_rng(1)
    mu, n = 0.4, 300
    scene = tcloth.Scene(gravity=(0, 0, 0))
    collider = {"sphere": lambda: scene.add_sphere((0.1, 0, 0), 0.7, friction=mu,
                                                   velocity=(0.3, 0, 0), thickness=0.02),
                "plane": lambda: scene.add_plane((0, 0.1, 0), (0.2, 1, 0.1), friction=mu,
                                                 thickness=0.02),
                "box": lambda: scene.add_box((0, 0, 0), (0.5, 0.3, 0.4), box_rotation(),
                                             friction=mu, velocity=(0, 0.2, -0.1),
                                             thickness=0.02),
                "cylinder": lambda: scene.add_cylinder((0, 0, 0), 0.4, 0.3, box_rotation(5),
                                                       friction=mu, velocity=(0.1, 0, 0.2),
                                                       thickness=0.02),
                "capsule": lambda: scene.add_capsule((0, 0, 0), 0.3, 0.4, box_rotation(7),
                                                     friction=mu, velocity=(0, 0.1, 0.2),
                                                     thickness=0.02)}[kind]()
    # particles scattered around the surface, some inside, with random velocities
    dirs = rng.normal(size=(n, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    x = np.empty((n, 3))
    for p in range(n):
        x[p] = collider["center"] + dirs[p] * rng.uniform(0.1, 1.0)
        phi, nrm = numpy_sdf(collider, x[p])
        x[p] += (rng.uniform(-0.03, 0.02) - phi) * nrm
    v = rng.normal(size=(n, 3))
    scene.add_particles(x, mass=0.05, velocities=v)
    sim = tcloth.Simulator(scene)
    f = sim.forces()
    in_contact = 0
    for p in range(n):
        phi, nrm = numpy_sdf(collider, x[p])
        fn = f[p] @ nrm
        ft = f[p] - fn * nrm
        v_rel = v[p] - collider["velocity"]
        vt = v_rel - (v_rel @ nrm) * nrm
        if phi >= 0.02:
            assert np.allclose(f[p], 0.0)
            continue
        in_contact += 1
        assert fn >= 0
        assert np.linalg.norm(ft) <= mu * fn * (1 + 1e-9) + 1e-12
        assert ft @ vt <= 1e-12
    assert in_contact > n // 3


def test_sliding_particle_loses_kinetic_energy_monotonically(f64):
    scene = tcloth.Scene(gravity=(0, -G, 0))
    m, k, thick = 0.1, 2000.0, 0.01
    scene.add_particles([[0, thick - m * G / k, 0]], mass=m, velocities=[[1.0, 0, 0.5]])
    scene.add_plane((0, 0, 0), (0, 1, 0), friction=0.3, thickness=thick, stiffness=k)
    sim = tcloth.Simulator(scene, "symplectic_euler", dt=1e-4)
    ke = []
    for _ in range(200):
        sim.step(20)
        ke.append(sim.energy()["kinetic"])
    assert np.all(np.diff(ke) <= 1e-12)
    # it stops after v0 / (mu g) seconds, having slid v0^2 / (2 mu g)
    assert ke[-1] < 1e-8
    slid = np.linalg.norm(sim.positions()[0, [0, 2]])
    assert slid == pytest.approx(1.25 / (2 * 0.3 * G), rel=0.01)


@pytest.mark.parametrize("shape", ["sphere", "box", "cylinder", "capsule"])
def test_dropped_particles_never_sink_deeper_than_energy_bound(f64, shape):
    m, k, thick, fall = 0.01, 5000.0, 0.005, 1.2      # fall: above any drop height here, m
    scene = tcloth.Scene(gravity=(0, -G, 0))
    if shape == "sphere":
        c = scene.add_sphere((0, 0, 0), 0.5, thickness=thick, stiffness=k, damping=0.2)
    elif shape == "cylinder":
        c = scene.add_cylinder((0, 0, 0), 0.5, 0.3, box_rotation(6), thickness=thick,
                               stiffness=k, damping=0.2)
    elif shape == "capsule":
        c = scene.add_capsule((0, 0, 0), 0.4, 0.3, box_rotation(6), thickness=thick,
                              stiffness=k, damping=0.2)
    else:
        c = scene.add_box((0, 0, 0), (0.5, 0.4, 0.6), box_rotation(2) @ np.diag([1, 1, 1]),
                          thickness=thick, stiffness=k, damping=0.2)
    rng = np.random.default_rng(3)
    top = np.array([[0.0, 1.0, 0.0]]) + rng.uniform(-0.2, 0.2, (40, 3)) * [1, 0, 1]
    scene.add_particles(top, mass=m)
    sim = tcloth.Simulator(scene, "symplectic_euler", dt=1e-4)
    # m g fall = k d^2 / 2 bounds the penetration d beyond the static deflection m g / k
    bound = np.sqrt(2 * m * G * fall / k) + m * G / k
    worst = np.inf
    for _ in range(60):
        sim.step(100)
        phis = [numpy_sdf(c, x)[0] for x in sim.positions()]
        worst = min(worst, min(phis))
    assert worst > thick - bound
    assert worst < thick


def test_particle_inside_box_is_pushed_out_along_nearest_face(f64):
    rot = box_rotation(4)
    scene = tcloth.Scene(gravity=(0, 0, 0))
    scene.add_box((1.0, 2.0, 3.0), (1.0, 0.5, 2.0), rot, stiffness=100.0)
    local = np.array([[0.8, 0.1, 0.3], [0.1, -0.4, 0.2], [0.2, 0.1, -1.9]])
    scene.add_particles(np.array([1.0, 2.0, 3.0]) + local @ rot.T, mass=1.0)
    sim = tcloth.Simulator(scene)
    f = sim.forces()
    expected_axes = [rot[:, 0], -rot[:, 1], -rot[:, 2]]
    for p, axis in enumerate(expected_axes):
        assert np.allclose(f[p] / np.linalg.norm(f[p]), axis, atol=1e-9)
    sim.step(3000)
    q = (sim.positions() - [1.0, 2.0, 3.0]) @ rot
    assert q[0, 0] > 1.0 and q[1, 1] < -0.5 and q[2, 2] < -2.0


def test_moving_sphere_drags_resting_particle_by_friction(f64):
    m, k, thick, mu, u = 0.01, 2000.0, 0.005, 0.5, 0.2
    scene = tcloth.Scene(gravity=(0, -G, 0))
    scene.add_sphere((0, 0, 0), 1.0, friction=mu, velocity=(u, 0, 0), thickness=thick,
                     stiffness=k)
    scene.add_particles([[0, 1.0 + thick - m * G / k, 0]], mass=m)
    sim = tcloth.Simulator(scene, "symplectic_euler", dt=1e-4)
    sim.step(100)
    a0 = sim.velocities()[0, 0] / sim.time
    assert a0 == pytest.approx(mu * G, rel=0.05)
    sim.step(4900)
    assert sim.velocities()[0, 0] == pytest.approx(u, rel=0.01)
    assert sim.positions()[0, 0] == pytest.approx(u * sim.time - u ** 2 / (2 * mu * G), abs=2e-3)


def test_contact_energy_reported_and_total_conserved_without_friction(f64):
    """A particle dropped 0.2 m onto a plane bounces off its penalty band (k = 500 N/m
    holds 0.1 kg at 0.196 J within 2.8 cm, inside the 5 cm thickness: the surface itself,
    where the contact stage would stop it, is never reached): total energy conserved."""
    scene = tcloth.Scene(gravity=(0, -G, 0))
    scene.add_plane((0, 0, 0), (0, 1, 0), thickness=0.05, stiffness=500.0, damping=0.0)
    scene.add_particles([[0, 0.25, 0]], mass=0.1)
    sim = tcloth.Simulator(scene, "verlet", dt=1e-4)
    e0 = sim.energy()["total"]
    seen_contact = 0.0
    for _ in range(300):
        sim.step(20)
        e = sim.energy()
        seen_contact = max(seen_contact, e["contact"])
        assert abs(e["total"] - e0) < 1e-3 * abs(e0)
    assert seen_contact > 0.5 * 0.1 * G * 0.2


BAD = [
    ("radius", lambda s: s.add_sphere((0, 0, 0), 0.0)),
    ("radius", lambda s: s.add_sphere((0, 0, 0), -1.0)),
    ("half_extents", lambda s: s.add_box((0, 0, 0), (1, 0, 1))),
    ("normal", lambda s: s.add_plane((0, 0, 0), (0, 0, 0))),
    ("rotation", lambda s: s.add_box((0, 0, 0), (1, 1, 1), rotation=np.diag([1, 1, -1]))),
    ("rotation", lambda s: s.add_box((0, 0, 0), (1, 1, 1), rotation=np.ones((3, 3)))),
    ("rotation", lambda s: s.add_box((0, 0, 0), (1, 1, 1), rotation=np.eye(2))),
    ("friction", lambda s: s.add_plane(friction=-0.1)),
    ("thickness", lambda s: s.add_sphere((0, 0, 0), 1.0, thickness=-0.01)),
    ("stiffness", lambda s: s.add_sphere((0, 0, 0), 1.0, stiffness=-5.0)),
    ("stiffness", lambda s: s.add_plane(stiffness=0.0)),
    ("velocity", lambda s: s.add_sphere((0, 0, 0), 1.0, velocity=(0, np.nan, 0))),
    ("center", lambda s: s.add_sphere((0, 0), 1.0)),
]


@pytest.mark.parametrize("linear_solver,tilt", [("auto", 0.0), ("cg", 0.0), ("auto", 0.5)],
                         ids=["multigrid", "block-jacobi", "tilted"])
def test_projective_on_a_frictionless_floor_keeps_the_horizontal_momentum(f64, linear_solver,
                                                                         tilt):
    """A cloth half lying on a frictionless floor and half raised in a ramp, its lying half
    sliding at 1 m/s: the floor pushes only along its normal and the rest is internal, so
    projective dynamics at one step per frame should keep the momentum along the floor
    (to 1e-3), with either global solve, and with the whole scene turned by ``tilt``
    (rad) about z (the floor's n n^T then couples x and y). CG solves to 1e-5: a solve's
    residual r moves the momentum by h^2 sum r (at the default 1e-3, 1.6e-3 of it in
    20 steps on the block-Jacobi path). With the collider's
    stiffness on A's diagonal in all three directions it grew by half in 20 steps
    (0.0500 -> 0.0748 kg m/s)."""
    c, s = np.cos(tilt), np.sin(tilt)
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    scene = tcloth.Scene(gravity=turn @ (0, -G, 0))
    scene.add_cloth(resolution=(10, 10), size=(0.5, 0.5), center=(0, 0.005, 0), mass=0.1,
                    structural=(400.0, 0.05), shear=(80.0, 0.02), flexion=(10.0, 0.005),
                    pinned=[])
    scene.add_plane(normal=turn @ (0, 1, 0), friction=0.0)
    x = scene.positions.copy()
    x[:, 1] += 0.3 * np.maximum(x[:, 0], 0.0)
    v = np.zeros_like(x)
    v[x[:, 0] < 0.0, 0] = 1.0
    sim = tcloth.Simulator(scene, "projective", dt=1 / 60, linear_solver=linear_solver,
                           cg_tol=1e-5)
    sim.set_state(positions=x @ turn.T, velocities=v @ turn.T)
    start = sim.momentum()[0] @ turn
    touching = 0
    for _ in range(20):
        sim.step()
        touching = max(touching, sim.contact_stats()["collider"])
    assert 0 < touching < scene.num_particles          # the diagonal differs between them
    along = (sim.momentum()[0] @ turn)[[0, 2]]
    np.testing.assert_allclose(along, start[[0, 2]], atol=1e-3 * start[0])


@pytest.mark.parametrize("argument,make", BAD, ids=[f"{a}-{k}" for k, (a, _) in enumerate(BAD)])
def test_bad_collider_input_names_the_argument(argument, make):
    with pytest.raises(SceneError, match=argument):
        make(tcloth.Scene())


def test_colliders_absent_from_scene_are_not_compiled(f64):
    scene = tcloth.Scene()
    scene.add_particles([[0, 1, 0]])
    scene.add_sphere((0, 0, 0), 0.5)
    scene.add_sphere((2, 0, 0), 0.5)
    sim = tcloth.Simulator(scene)
    groups = sim.model.colliders.groups
    assert [(SHAPES[g.shape].name, g.first, g.count) for g in groups] == [("sphere", 0, 2)]
    plain = tcloth.Scene()
    plain.add_particles([[0, 1, 0]])
    sim = tcloth.Simulator(plain)
    assert sim.model.colliders.count == 0
    assert not any(isinstance(t, Colliders) for t in sim.integrator.forces.terms)


@ti.kernel
def _ray_hits(table: ti.template(), o: ti.types.ndarray(), d: ti.types.ndarray(),
              out: ti.types.ndarray()):
    for k in range(out.shape[0]):
        origin = ti.Vector([o[k, 0], o[k, 1], o[k, 2]])
        direction = ti.Vector([d[k, 0], d[k, 1], d[k, 2]])
        out[k] = SHAPES[ti.static(table.groups[0].shape)].ray_hit(table.data[0], origin,
                                                                  direction, 0.0)


SHAPE_BUILDERS = {
    "sphere": lambda s: s.add_sphere((0.1, 0.2, 0), 0.5),
    "plane": lambda s: s.add_plane((0, 0.1, 0), (0.2, 1, 0.1)),
    "box": lambda s: s.add_box((0, 0, 0.1), (0.5, 0.3, 0.4), box_rotation(1)),
    "cylinder": lambda s: s.add_cylinder((0, 0.1, 0), 0.4, 0.3, box_rotation(5)),
    "capsule": lambda s: s.add_capsule((0.1, 0, 0), 0.3, 0.4, box_rotation(7)),
}


@pytest.mark.parametrize("kind", [s.name for s in SHAPES if not s.meshed])
def test_every_shape_s_ray_hit_enters_where_its_distance_vanishes(f64, kind):
    """The renderer and the contact stage's sweeps use each shape's ray hit: against the
    NumPy signed distance, a ray from outside enters where phi = 0, nothing on it before
    is inside, and a ray that misses stays outside all along."""
    scene = tcloth.Scene()
    collider = SHAPE_BUILDERS[kind](scene)
    table = ColliderTable(scene.colliders)
    rng = np.random.default_rng(8)
    n = 400
    dirs = rng.normal(size=(n, 3))
    o = collider["center"] + 2.5 * dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    aim = collider["center"] + rng.uniform(-0.8, 0.8, (n, 3)) - o
    d = aim / np.linalg.norm(aim, axis=1, keepdims=True)
    t = np.zeros(n)
    _ray_hits(table, o, d, t)
    hits = 0
    for k in range(n):
        if numpy_sdf(collider, o[k])[0] <= 0:
            continue
        before = [numpy_sdf(collider, o[k] + s * d[k])[0] for s in np.linspace(0, 4, 400)
                  if t[k] < 0 or s < t[k] - 1e-9]
        assert min(before) > -1e-9, (k, t[k])
        if t[k] > 0:
            hits += 1
            assert abs(numpy_sdf(collider, o[k] + t[k] * d[k])[0]) < 1e-9
    assert 0.2 * n < hits < n
