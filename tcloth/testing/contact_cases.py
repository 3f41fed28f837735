"""The contact stress set (``CASES``: each a scene builder with its time span and the
explicit integrators' dt) and ``run_case``, which runs one and checks it with NumPy alone
at every step: edge-triangle crossings (``crossings``; zero unless the scene started
crossed), particles inside a collider or whose path went through a thin box
(``colliders``), the thrown cloths' order (each cloth's centre particle stays on the side
of the other it started on), their linear momentum, and no blow-up.

Cases:
  - ``thrown_3``, ``thrown_10``: two 24 x 24 cloths of 0.5 m thrown at each other at 3 and
    10 m/s relative, no gravity, thickness 6 mm; ``thrown_unequal``: 12 x 12 cloths of 0.05
    and 0.1 kg at 1 m/s each;
  - ``twist``: a 32 x 32 cloth whose two ends turn in opposite directions (its pinned rows
    are moved from Python every step) until it wrinkles onto itself;
  - ``fold``, ``pile``: scenes/fold.py and scenes/cloth_pile.py (``scripts``);
  - ``box_10``, ``sphere_10``: a 24 x 24 cloth falling at 10 m/s onto a box 1 cm thick and
    onto a sphere.

``sliding``: a small cloth sliding over a large one without friction, on a frictionless
floor; nothing takes horizontal momentum from the two cloths, so the upper one should keep
its speed and the lower stay at rest (docs/contact.md).
"""
import math
import time

import numpy as np
import taichi as ti

import tcloth

from .colliders import passes_through_boxes, signed_distances
from .crossings import count_crossings, triangle_edges
from .scripts import script

CLOTH = {"structural": (400.0, 0.05), "shear": (80.0, 0.02), "flexion": (10.0, 0.005),
         "pinned": []}


def thrown(speed, res=24, masses=(0.1, 0.1), size=0.5, gap=0.1):
    """Two cloths facing each other ``gap`` m apart, the upper one shifted and turned a
    little, thrown together at ``speed`` relative. Returns (scene, positions, velocities,
    the two cloths)."""
    scene = tcloth.Scene(gravity=(0.0, 0.0, 0.0))
    a = scene.add_cloth(resolution=(res, res), size=(size, size), center=(0.0, gap / 2, 0.0),
                        mass=masses[0], **CLOTH)
    b = scene.add_cloth(resolution=(res, res), size=(size, size),
                        center=(0.02, -gap / 2, 0.03), mass=masses[1], **CLOTH)
    scene.set_self_collision(thickness=0.006)
    x = scene.positions
    ids = b.particles.ravel()
    c, s = math.cos(0.3), math.sin(0.3)
    centre = x[ids].mean(axis=0)
    x[ids] = (x[ids] - centre) @ np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]).T + centre
    v = np.zeros_like(x)
    v[a.particles.ravel(), 1] = -speed / 2
    v[ids, 1] = speed / 2
    return scene, x, v, (a, b)


def falling(collider, speed=10.0, res=24, height=0.3):
    """A 24 x 24 cloth at ``height`` falling at ``speed`` onto a box 1 cm thick (its top at
    0.105) or a sphere (its top at 0.22) on a plane."""
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0))
    cloth = scene.add_cloth(resolution=(res, res), size=(0.6, 0.6), center=(0.0, height, 0.0),
                            mass=0.2, **CLOTH)
    if collider == "box":
        scene.add_box((0.0, 0.1, 0.0), (0.25, 0.005, 0.25), friction=0.3)
    else:
        scene.add_sphere((0.0, 0.1, 0.0), 0.12, friction=0.3)
    scene.add_plane((0.0, -0.3, 0.0), (0.0, 1.0, 0.0), friction=0.3)
    scene.set_self_collision(thickness=0.006)
    v = np.zeros_like(scene.positions)
    v[cloth.particles.ravel(), 1] = -speed
    return scene, scene.positions, v, (cloth,)


def twisted(res=32):
    """A 32 x 32 cloth hanging between two rows held at its ends, which turn in opposite
    directions (``twist_rows``)."""
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0))
    cloth = scene.add_cloth(resolution=(res, res), size=(0.6, 0.6), center=(0.0, 0.5, 0.0),
                            mass=0.2, plane="xz", **{**CLOTH, "pinned": [
                                (i, j) for i in range(res) for j in (0, res - 1)]})
    scene.set_self_collision(thickness=0.004)
    return scene, scene.positions, scene.velocities, (cloth,)


TWIST_RATE = 2.0 * math.pi * 0.75       # rad/s each end, in opposite directions


def twist_rows(sim, cloth, x_rest, t):
    """Move the held end rows of ``twisted`` to their turned positions at time t (about
    the cloth's axis along z), with the matching velocities."""
    res = cloth.particles.shape[0]
    x, v = sim.positions(), sim.velocities()
    for j, sign in ((0, 1.0), (res - 1, -1.0)):
        ids = cloth.particles[j]
        angle = sign * TWIST_RATE * t
        c, s = math.cos(angle), math.sin(angle)
        rest = x_rest[ids] - [0.0, 0.5, 0.0]
        x[ids, 0] = c * rest[:, 0] - s * rest[:, 1]
        x[ids, 1] = s * rest[:, 0] + c * rest[:, 1] + 0.5
        x[ids, 2] = rest[:, 2]
        v[ids, 0] = -sign * TWIST_RATE * (x[ids, 1] - 0.5)
        v[ids, 1] = sign * TWIST_RATE * x[ids, 0]
        v[ids, 2] = 0.0
    sim.set_state(positions=x, velocities=v)


def script_scene(name):
    module, _ = script(name)
    scene = module.build()
    return scene, scene.positions, scene.velocities, tuple(scene.cloths)


CASES = {
    "thrown_3": (lambda: thrown(3.0), 0.3, 1e-4),
    "thrown_10": (lambda: thrown(10.0), 0.2, 5e-5),
    "thrown_unequal": (lambda: thrown(2.0, res=12, masses=(0.05, 0.1)), 0.3, 1e-4),
    "twist": (twisted, 1.0, 1e-4),
    "fold": (lambda: script_scene("fold"), 1.5, 2.5e-4),
    "pile": (lambda: script_scene("cloth_pile"), 1.5, 2.5e-4),
    "box_10": (lambda: falling("box"), 0.4, 5e-5),
    "sphere_10": (lambda: falling("sphere"), 0.4, 5e-5),
}
EXPLICIT = ("forward_euler", "symplectic_euler", "verlet", "rk4")


def side(x, point, cloth):
    """+1 or -1: the side of ``cloth`` particle ``point`` lies on: of the plane through
    the cloth's particles' mean whose normal is the sum of its triangles' area normals
    (the winding is the cloth's own, so the sign is comparable from one state to the
    next). The nearest triangle's normal, used before, flips where a cloth that bounced
    off the other crumples, with the two cloths far apart."""
    tri = cloth.triangles
    a, b, c = x[tri[:, 0]], x[tri[:, 1]], x[tri[:, 2]]
    normal = np.cross(b - a, c - a).sum(axis=0)
    return 1 if np.dot(x[point] - x[cloth.particles.ravel()].mean(axis=0), normal) >= 0 else -1


def centre(cloth):
    return cloth.particles[cloth.particles.shape[0] // 2, cloth.particles.shape[1] // 2]


def closing_speed(v, cloths):
    """How fast two thrown cloths' centres of mass approach each other along the throw
    (the y axis; the first cloth is thrown down): the throw's speed until they meet."""
    a, b = (v[c.particles.ravel()].mean(axis=0) for c in cloths)
    return float(b[1] - a[1])


def order_kept(x, cloths, sides):
    """Each thrown cloth's centre particle is on the side of the other cloth it started
    on (``sides``: the start's ``side`` values): a cloth that passed wholly through the
    other in one step shows no crossing at either end, but is on the other side."""
    a, b = cloths[0], cloths[1]
    return (side(x, centre(a), b), side(x, centre(b), a)) == sides


def guard_step(sim, x, v, dt):
    """The contact stage on the free-flight motion x -> x + dt v; returns (x1, v1). The
    fields are the simulator's two states' (the stage's kernels compile once a
    simulator, as for its own steps)."""
    real = sim.state.x.dtype
    s_in, s_out = sim._states
    fields = (s_in.x, s_out.x, s_out.v)
    for f, value in zip(fields, (x, x + dt * v, v)):
        f.from_numpy(value.astype(np.float64 if real == ti.f64 else np.float32))
    sim.contact.end_step(*fields, 0.0, dt)
    return fields[1].to_numpy().astype(np.float64), fields[2].to_numpy().astype(np.float64)


def run_case(name, integrator, dt, seconds=None, chunk=1, build=None, options=None):
    """Run one case (dt None: the case's explicit dt; ``build``: a smaller version of the
    case's scene, as the tests run); returns a dict of metrics, each checked after every
    step. ``chunk`` > 1 steps that many steps in one call (a batch) and checks the state
    after each chunk only; "through" is then None (the paths through a box need each
    step's start)."""
    if chunk > 1 and name == "twist":
        raise ValueError("the twist case moves its rows every step: chunk must be 1")
    case_build, span, explicit_dt = CASES[name]
    scene, x, v, cloths = (build or case_build)()
    dt = explicit_dt if dt is None else dt
    steps = int(round((seconds or span) / dt))
    sim = tcloth.Simulator(scene, integrator, dt=dt, **(options or {}))
    sim.set_state(positions=x, velocities=v)
    triangles = scene.triangles
    edges = triangle_edges(triangles)
    momentum0 = sim.momentum()[0]
    x_rest = scene.positions
    crossings = [count_crossings(sim.positions(), triangles, edges)]
    inside, through, order, times, blew_up, contacts = 0.0, 0, True, [], None, 0
    closest = math.inf
    stepped = 0
    sides = None
    if name.startswith("thrown"):
        sides = (side(x, centre(cloths[0]), cloths[1]), side(x, centre(cloths[1]), cloths[0]))
    for k in range(0, steps, chunk):
        if name == "twist":
            twist_rows(sim, cloths[0], x_rest, sim.time)
        x0, t0 = sim.positions(), sim.time
        n = min(chunk, steps - k)
        start = time.perf_counter()
        try:
            sim.step(n)
        except tcloth.InstabilityError as e:
            blew_up = str(e)
            break
        times.append((time.perf_counter() - start) / n)
        stepped += n
        x1 = sim.positions().astype(np.float64)
        crossings.append(count_crossings(x1, triangles, edges))
        contacts = max(contacts, sum(sim.self_contacts().values()))
        if scene.colliders:
            nearest = float(signed_distances(scene, x1, sim.time).min())
            inside = max(inside, -min(nearest, 0.0))
            closest = min(closest, nearest)
            if chunk == 1:
                through += passes_through_boxes(scene, x0, x1, t0, dt)
        if sides is not None:
            order &= order_kept(x1, cloths, sides)
    stats = sim.contact_stats()
    scale = float(np.sum(scene.masses)) * float(np.abs(v).max())
    return {"crossings_start": crossings[0], "crossings_max": max(crossings[1:] or [0]),
            "inside_max": inside, "closest_collider_m": closest,
            "through": through if chunk == 1 else None,
            "order_kept": order,
            "momentum_drift": float(np.abs(sim.momentum()[0] - momentum0).max() / scale)
            if sides is not None else None,
            "closing_speed_end": closing_speed(sim.velocities(), cloths)
            if sides is not None else None,
            "ms_per_step": 1e3 * float(np.median(times)) if times else math.nan,
            "steps": stepped, "blew_up": blew_up, "contacts_max": contacts,
            **{key: stats.get(key) for key in ("failsafe_steps", "failsafe_vertices",
                                               "guard_corrections", "collider_paths_cut",
                                               "swept_searches", "rebuilds")}}


def sliding(lower=(24, 1.2, 0.3), upper=(8, 0.3, 0.02)):
    """(scene, lower cloth, upper cloth, velocities at the start): the lower cloth
    (resolution, size in m, mass in kg) lying on a frictionless floor, the upper one 9 mm
    above it, a size of its own from the lower one's middle, moving at 1 m/s."""
    s = tcloth.Scene(gravity=(0.0, -9.81, 0.0))
    (n, size, mass), (m, upper_size, upper_mass) = lower, upper
    low = s.add_cloth(resolution=(n, n), size=(size, size), center=(0.0, 0.006, 0.0),
                      mass=mass, **CLOTH)
    up = s.add_cloth(resolution=(m, m), size=(upper_size, upper_size),
                     center=(-upper_size, 0.015, 0.0), mass=upper_mass, **CLOTH)
    s.add_plane((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), friction=0.0)
    s.set_self_collision(thickness=0.006)
    v = np.zeros((s.num_particles, 3))
    v[up.particles.ravel(), 0] = 1.0
    return s, low, up, v
