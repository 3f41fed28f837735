"""Colliders: sphere, plane and box with penalty contact and Coulomb friction (lecture 4).

Detection: the signed distance phi(x) to each shape and its outward unit normal n.
Resolution: a particle closer than the collider's ``thickness`` is pulled by a temporary
zero-rest-length spring of stiffness k to the closest surface point pushed out by the
thickness: f_n = k (thickness - phi) n, minus a normal damping 2 zeta sqrt(k m) v_n
(zeta = ``damping``, a ratio of critical; the total is clamped to push only). Friction
opposes the tangential velocity relative to the collider, |f_t| <= mu |f_n|:

    f_t = -mu |f_n| v_t / max(|v_t|, eps),   eps = ``stick_velocity`` (m/s).

Below eps the friction is a viscous regularisation of sticking: a particle held by static
friction on an incline creeps at eps tan(theta) / mu. For explicit integrators keep
eps > mu g dt / 2 so that the regularised stick regime is itself stable.

All colliders of a scene are handled by one kernel launch; kinds the scene lacks are
compiled out; a scene without colliders launches nothing.
"""
import numpy as np
import taichi as ti

from .runtime import serial

SPHERE, PLANE, BOX = 0, 1, 2
KINDS = ("sphere", "plane", "box")
# Record layout, one row per collider (width RECORD):
#   0-2 centre / point, 3-5 velocity, 6-8 radius (6) | normal | half extents,
#   9-17 rotation (row-major, box only), 18 thickness, 19 stiffness, 20 damping ratio,
#   21 friction mu, 22 stick velocity eps.
RECORD = 23


def pack(colliders):
    """Scene collider dicts -> ((C, RECORD) float64 rows sorted by kind, ranges), where
    ranges[kind] = (first row, count) is a static (hashable) tuple for the kernels."""
    rows, ranges = [], []
    for kind in KINDS:
        start = len(rows)
        for c in colliders:
            if c["kind"] != kind:
                continue
            r = np.zeros(RECORD)
            r[0:3] = c["center"]
            r[3:6] = c["velocity"]
            r[6:9] = {"sphere": lambda: (c["radius"], 0, 0), "plane": lambda: c["normal"],
                      "box": lambda: c["half_extents"]}[kind]()
            r[9:18] = c.get("rotation", np.eye(3)).ravel()
            r[18:23] = (c["thickness"], c["stiffness"], c["damping"], c["friction"],
                        c["stick_velocity"])
            rows.append(r)
        ranges.append((start, len(rows) - start))
    return np.array(rows).reshape(-1, RECORD), tuple(ranges)


@ti.func
def _vec(rec, start):
    return ti.Vector([rec[start], rec[start + 1], rec[start + 2]])


@ti.func
def signed_distance(kind: ti.template(), rec, x, t):
    """(phi, n): signed distance of x to the collider at time t and the outward normal."""
    c = _vec(rec, 0) + t * _vec(rec, 3)
    phi = 0.0
    n = ti.Vector([0.0, 1.0, 0.0])
    if ti.static(kind == SPHERE):
        d = x - c
        length = d.norm()
        phi = length - rec[6]
        if length > 0.0:
            n = d / length
    elif ti.static(kind == PLANE):
        n = _vec(rec, 6)
        phi = (x - c).dot(n)
    else:
        rot = ti.Matrix([[rec[9], rec[10], rec[11]], [rec[12], rec[13], rec[14]],
                         [rec[15], rec[16], rec[17]]])
        q = rot.transpose() @ (x - c)
        d = ti.abs(q) - _vec(rec, 6)
        outside = ti.max(d, 0.0)
        nl = ti.Vector([0.0, 0.0, 0.0])
        if outside.norm() > 0.0:
            phi = outside.norm()
            nl = outside / phi * ti.math.sign(q)
        else:
            # inside: the nearest face is the axis of least penetration
            axis = 0
            if d[1] > d[axis]:
                axis = 1
            if d[2] > d[axis]:
                axis = 2
            phi = d[axis]
            nl[axis] = 1.0 if q[axis] >= 0.0 else -1.0
        n = rot @ nl
    return phi, n


@ti.func
def contact_force(kind: ti.template(), rec, x, v, m, t):
    """Penalty normal force plus regularised Coulomb friction on one particle."""
    phi, n = signed_distance(kind, rec, x, t)
    f = ti.Vector([0.0, 0.0, 0.0])
    depth = rec[18] - phi
    if depth > 0.0:
        k = rec[19]
        v_rel = v - _vec(rec, 3)
        vn = v_rel.dot(n)
        fn = ti.max(k * depth - 2.0 * rec[20] * ti.sqrt(k * m) * vn, 0.0)
        vt = v_rel - vn * n
        speed = vt.norm()
        f = fn * n - rec[21] * fn / ti.max(speed, rec[22]) * vt
    return f


@ti.kernel
def collide(x: ti.template(), v: ti.template(), mass: ti.template(), inv_mass: ti.template(),
            records: ti.template(), ranges: ti.template(), t: float, f_out: ti.template()):
    """Add the contact forces of every collider to f_out; pinned particles are skipped.

    records: field of collider rows; ranges[kind] = (first row, count), static.
    """
    ti.loop_config(serialize=ti.static(serial(f_out)))
    for p in range(f_out.shape[0]):
        if inv_mass[p] > 0.0:
            acc = ti.Vector([0.0, 0.0, 0.0])
            for kind in ti.static(range(3)):
                if ti.static(ranges[kind][1] > 0):
                    for c in range(ranges[kind][0], ranges[kind][0] + ranges[kind][1]):
                        acc += contact_force(kind, records[c], x[p], v[p], mass[p], t)
            f_out[p] += acc


@ti.kernel
def contact_energy(x: ti.template(), inv_mass: ti.template(), records: ti.template(),
                   ranges: ti.template(), t: float, out: ti.template()):
    """out[0] = sum over contacts of k/2 (thickness - phi)^2, J."""
    out[0] = 0
    for p in range(x.shape[0]):
        if inv_mass[p] > 0.0:
            for kind in ti.static(range(3)):
                if ti.static(ranges[kind][1] > 0):
                    for c in range(ranges[kind][0], ranges[kind][0] + ranges[kind][1]):
                        rec = records[c]
                        phi, _ = signed_distance(kind, rec, x[p], t)
                        depth = rec[18] - phi
                        if depth > 0.0:
                            out[0] += ti.cast(0.5 * rec[19] * depth * depth, out.dtype)
