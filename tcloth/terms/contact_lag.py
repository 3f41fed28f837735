"""The contact law's parts that backward Euler's and VBD's incremental potential read
beside the penalty (``self_contact.py``): each row's normal force, normal and weights
lagged at the step's start (``Lagged``), the normal damping and friction as convex
dissipation potentials of the end velocity with them, and the penalty's gradient."""
import taichi as ti

from .. import runtime
from ..runtime import serial
from .colliders import add_dissipation


@ti.func
def unit_normal(g, d):
    """g over its length d (zero where d is)."""
    return g / ti.max(d, 1e-30)


@ti.data_oriented
class Lagged:
    """What the contact law keeps per row of the candidate list for backward Euler and
    VBD: the lagged normal force, normal and weights at the step's start, and the
    Hessian's weights, penalty and dissipation blocks (``capacity`` rows)."""

    def __init__(self, capacity):
        real = runtime.real()
        self.capacity = capacity
        self.fn = ti.field(real, shape=capacity)
        self.n = ti.Vector.field(3, real, shape=capacity)
        self.alpha0 = ti.Vector.field(4, real, shape=capacity)
        self.alpha = ti.Vector.field(4, real, shape=capacity)
        self.penalty = ti.Matrix.field(3, 3, real, shape=capacity)
        self.damping = ti.Matrix.field(3, 3, real, shape=capacity)


@ti.func
def lagged(cl, c, x0):
    """(fn, n, alpha) of candidate c at the step's start x0: its normal force k (T - d)
    (0 where it does not touch), normal and weights."""
    prm = ti.static(cl.table.params)
    alpha, g = cl.gap(cl.ids[c], cl.kind[c], x0)
    d = g.norm()
    fn = 0.0
    if cl.repels[c] and d > 0.0 and d < prm[0]:
        fn = prm[1] * (prm[0] - d)
    return fn, unit_normal(g, d), alpha


@ti.kernel
def lag_rows(cl: ti.template(), lag: ti.template(), count: ti.i32, x0: ti.template()):
    """Each candidate's normal force, normal and weights at the step's start."""
    ti.loop_config(serialize=ti.static(serial(cl.ids)))
    for c in range(count):
        lag.fn[c], lag.n[c], lag.alpha0[c] = lagged(cl, c, x0)


@ti.func
def dissipation(cl, ids, fn0, n0, alpha0, x, x0, h, majorant: ti.template()):
    """(energy, gradient, Hessian) in the relative motion sum_k alpha0_k x_k of a contact's
    normal damping and friction as convex potentials of the end velocity (the colliders'
    ``add_dissipation`` between two moving sides), with its lagged normal force fn0,
    normal n0 and weights alpha0 (``lagged``); no damping where every particle of the
    contact is pinned; friction's block its majorant's with ``majorant``."""
    prm = ti.static(cl.table.params)
    e = 0.0
    g = ti.Vector.zero(float, 3)
    block = ti.Matrix.zero(float, 3, 3)
    if fn0 > 0.0:
        w = cl.inverse_mass(ids, alpha0)
        v = ti.Vector.zero(float, 3)
        for j in ti.static(range(4)):
            v += alpha0[j] * (x[ids[j]] - x0[ids[j]]) / h
        cd = 0.0
        if w > 0.0:
            cd = 2.0 * prm[3] * ti.sqrt(prm[1] / w)
        e, g, block = add_dissipation(e, g, block, v, n0, fn0, cd, prm[2], prm[4], h,
                                      majorant)
    return e, g, block


@ti.func
def row_dissipation(cl, lag, c, x, x0, h, majorant: ti.template()):
    """``dissipation`` of candidate c with its values lagged by ``lag_rows``."""
    return dissipation(cl, cl.ids[c], lag.fn[c], lag.n[c], lag.alpha0[c], x, x0, h, majorant)


@ti.func
def penalty_gradient(cl, c, x):
    """(ids, alpha, depth T - d, the penalty's gradient in the gap -k (T - d) n) of
    candidate c at x: the gradient zero where it does not touch."""
    prm = ti.static(cl.table.params)
    ids = cl.ids[c]
    alpha, g = cl.gap(ids, cl.kind[c], x)
    d = g.norm()
    depth = prm[0] - d
    grad = ti.Vector.zero(float, 3)
    if cl.repels[c] and depth > 0.0:
        grad = -prm[1] * depth * unit_normal(g, d)
    return ids, alpha, depth, grad
