"""Pressure: the gas enclosed by a closed cloth (a balloon, a cushion), isothermal.

Each closed cloth is a chamber holding a fixed amount of ideal gas at constant temperature
(Boyle: P V = P0 V0) in ambient air at pressure P_a. With V the volume its triangles
enclose, x_a . (x_b x x_c) / 6 summed over them (outward winding), its potential is

    U(V) = -P0 V0 ln(V / V0) + P_a (V - V0),

and the force on particle i is (P0 V0 / V - P_a) dV/dx_i, with dV/dx_a = x_b x x_c / 6 from
each triangle (a, b, c) around it: the net pressure P(V) - P_a times a third of the
area-weighted normals. The forces of a chamber sum to zero, as do their torques. P0 - P_a
is the ``pressure`` given at the rest volume V0 (by default the volume of the scene's
positions). Blender and Houdini Vellum give cloth a pressure of this kind.

Near ambient pressure the gas is far stiffer than the cloth (a volume change dV costs
P0 V0 / V^2 dV^2 / 2: at P_a = 1e5 Pa the gas of a 0.1 m balloon of the mesh cloth's
default springs resists its breathing seven times as stiffly as the springs, which then
rings at 220 Hz), so every implicit solver takes it implicitly. With g = dV/dx (every
particle's dV/dx_i), k = P0 V0 / V^2 and p = P0 V0 / V - P_a, U's Hessian is

    k g g^T - p d2V/dx2,   d2V/dx_a dx_b = -[x_c]_x / 6 for each triangle (a, b, c),

a rank-one part dense over the chamber (PSD) and the area-normal derivative, skew
3 x 3 blocks between the corners of each triangle with no diagonal blocks (V is linear in
each particle alone); indefinite.

  - Backward Euler: U in the incremental potential, as a pair term: ``add_incremental``
    (U and -p g), ``prepare_blocks``, the diagonal blocks k g_i g_i^T (block Jacobi's
    preconditioner) and ``add_product``, the Hessian less those blocks times a vector
    (the rank-one part through one dot product g . v per chamber): exact where backward
    Euler's truncated Newton-CG asks for it (``exact``), else the rank-one part alone,
    positive semi-definite, as the membrane drops its indefinite parts.
  - VBD: a Jacobi pair term (gradient and diagonal blocks held through an iteration's
    colour passes). Every particle of a chamber then moves at once, and with the exact
    blocks each would make the whole volume change a Newton step asks for, n times too
    much (it diverges). Its blocks are instead k S |g_i| n_i n_i^T (``jacobi``;
    n_i = g_i / |g_i|, S = sum_j |g_j| over the chamber), which bound the rank-one part
    by Cauchy-Schwarz, (g . v)^2 <= S sum_i (g_i . v_i)^2 / |g_i|, with equality for a
    uniform normal displacement: the breathing mode is solved in one update, and no
    mode overshoots.
  - Projective dynamics: in the force residual, with the rank-one part at the step's start,
    k0 g0 g0^T, in the global matrix (``GasStiffness``, a coupling of CG's products): a
    quasi-Newton step that carries the breathing mode's stiffness.
  - XPBD: one constraint per chamber (``project``), its multiplier started at 0 each
    substep as the springs' are: Newton's method on the applied pressure q = p(V(x)) with
    x = x_pred + h^2 M^-1 g_s q, which is XPBD's update for the constraint C = -p / k with
    compliance 1 / (k h^2), both at the current volume, and multiplier h^2 q. The moves
    go along g_s, the gradient at the substep's start, so that they add up to
    h^2 M^-1 g_s q: along each pass's own g (XPBD's usual way) they add up along a path
    of gradients that a gas turns by the whole inflation, and the fixed point of a soft
    balloon came out 6% of its inflation short (0.03% along g_s). Starting q at the
    substep's p with that force in the prediction instead leaves the springs' share to
    the iterations alone: a stiff gas then over-inflates the unconverged iterate and gains
    energy.
"""
import taichi as ti

from .. import runtime
from ..features.pressure import PRESSURE, potential
from ..runtime import serial
from .base import ConstantMatrix, Term, add_or_set


@ti.kernel
def _volumes(term: ti.template(), x: ti.template()):
    term.chamber_volumes(x)


@ti.data_oriented
class Pressure(Term):
    """The enclosed gas of the scene's chambers (``Scene.set_pressure``)."""
    name = "pressure"
    feature = PRESSURE
    implicit = "potential"
    projective = "force"
    provides = frozenset({"couplings", "constant_matrix", "constraints"})
    # exact: ``add_product`` multiplies by the exact Hessian (backward Euler's truncated
    # Newton-CG on exact_hessian), else by the rank-one part; jacobi: ``diagonal_block`` is
    # the bound for a Jacobi update (VBD)
    options = {"exact": False, "jacobi": False}

    @staticmethod
    def present(model):
        return model.pressure is not None

    def __init__(self, model, exact=False, jacobi=False):
        pressure = model.pressure
        self.tris, self.chamber, self.gas = pressure.triangles, pressure.chamber, pressure.gas
        self.inv_mass = model.inv_mass
        self.start, self.entries = pressure.start, pressure.entries
        count, n, real = self.gas.shape[0], model.particle_count, runtime.real()
        # per chamber (f64): V; sum |x_a| |x_b x x_c| / 6 (the scale of V's rounding);
        # S = sum |g_i|; g . v (``add_product``); XPBD's applied pressure, dV/dq / h^2 and
        # h^2 times the applied pressure's change (``project``)
        self.volume, self.scale, self.bound, self.dot, self.lam, self.weight, self.dlam = (
            ti.field(ti.f64, shape=count) for _ in range(7))
        # (k, p) at ``prepare_blocks``
        self.block_terms = ti.Vector.field(2, ti.f64, shape=count)
        # per particle: dV/dx_i, the positions of the last ``prepare_blocks`` and XPBD's
        # dV/dx_i at the substep's start
        self.grad_v, self.x_at, self.grad_start = (
            ti.Vector.field(3, real, shape=n) for _ in range(3))
        self.exact, self.jacobi = bool(exact), bool(jacobi)

    def batch_obstacle(self):
        if not serial(self.tris):
            return f"the pressure's {self.tris.shape[0]} triangles run on several threads"
        return None

    @ti.func
    def chamber_volumes(self, x):
        """Each chamber's volume into ``volume`` (f64)."""
        tris, chamber, volume = ti.static(self.tris, self.chamber, self.volume)
        ti.loop_config(serialize=ti.static(serial(volume)))
        for c in range(volume.shape[0]):
            volume[c] = 0
        ti.loop_config(serialize=ti.static(serial(tris)))
        for k in range(tris.shape[0]):
            a, b, c = x[tris[k][0]], x[tris[k][1]], x[tris[k][2]]
            volume[chamber[k]] += ti.cast(a.dot(b.cross(c)) / 6.0, ti.f64)

    @ti.func
    def accumulate(self, x, v, t, f_out):
        """Each chamber's volume, then (P0 V0 / V - P_a) dV/dx on every triangle's corners."""
        tris, chamber, gas, volume = ti.static(self.tris, self.chamber, self.gas, self.volume)
        self.chamber_volumes(x)
        ti.loop_config(serialize=ti.static(serial(tris)))
        for k in range(tris.shape[0]):
            i = tris[k]
            g = gas[chamber[k]]
            p = ti.cast(g[0] / volume[chamber[k]] - g[1], float)
            for j in ti.static(range(3)):
                b, c = x[i[(j + 1) % 3]], x[i[(j + 2) % 3]]
                f_out[i[j]] += p * b.cross(c) / 6.0

    def energy(self, x, t, out):
        """-P0 V0 ln(V / V0) + P_a (V - V0) summed over the chambers, in f64."""
        _volumes(self, x)
        return potential(self.gas.to_numpy(), self.volume.to_numpy())

    @ti.func
    def chamber_of(self, p):
        """Particle p's chamber, or -1 for a particle in no chamber."""
        c = -1
        if self.start[p] < self.start[p + 1]:
            c = self.chamber[self.entries[self.start[p]][0]]
        return c

    @ti.func
    def volume_gradient(self, p, x):
        """dV/dx_p at x: x_b x x_c / 6 summed over p's triangles (b, c the corners after p)."""
        g = ti.Vector.zero(float, 3)
        for k in range(self.start[p], self.start[p + 1]):
            ids, slot = self.tris[self.entries[k][0]], self.entries[k][1]
            g += x[ids[(slot + 1) % 3]].cross(x[ids[(slot + 2) % 3]]) / 6.0
        return g

    @ti.func
    def normal_derivative(self, p, x, v):
        """(d2V/dx2 v)_p at x: (v_b x x_c + x_b x v_c) / 6 summed over p's triangles."""
        out = ti.Vector.zero(float, 3)
        for k in range(self.start[p], self.start[p + 1]):
            ids, slot = self.tris[self.entries[k][0]], self.entries[k][1]
            b, c = ids[(slot + 1) % 3], ids[(slot + 2) % 3]
            out += (v[b].cross(x[c]) + x[b].cross(v[c])) / 6.0
        return out

    # -- backward Euler and VBD ------------------------------------------------------------
    @ti.kernel
    def _incremental(self, x: ti.template(), with_grad: ti.template(), acc: ti.template(),
                     grad: ti.template()):
        tris, gas, volume, scale = ti.static(self.tris, self.gas, self.volume, self.scale)
        self.chamber_volumes(x)
        ti.loop_config(serialize=ti.static(serial(scale)))
        for c in range(scale.shape[0]):
            scale[c] = 0
        ti.loop_config(serialize=ti.static(serial(tris)))
        for k in range(tris.shape[0]):
            a, b, c = x[tris[k][0]], x[tris[k][1]], x[tris[k][2]]
            scale[self.chamber[k]] += ti.cast(a.norm() * b.cross(c).norm() / 6.0, ti.f64)
        ti.loop_config(serialize=ti.static(serial(volume)))
        for c in range(volume.shape[0]):
            g, v = gas[c], volume[c]
            u = -g[0] * ti.log(v / g[2]) + g[1] * (v - g[2])
            acc[0] += ti.cast(u, acc.dtype)
            acc[1] += ti.cast(ti.abs(u) + (g[0] / ti.abs(v) + g[1]) * scale[c], acc.dtype)
        if ti.static(with_grad):
            ti.loop_config(serialize=ti.static(serial(grad)))
            for p in range(grad.shape[0]):
                c = self.chamber_of(p)
                if c >= 0:
                    net = ti.cast(gas[c][0] / volume[c] - gas[c][1], float)
                    grad[p] -= net * self.volume_gradient(p, x)

    def add_incremental(self, x, x0, h, with_grad, acc, grad):
        """acc[0] += U at x (acc[1] a bound on its rounding: |U| and V's rounding scale
        times |dU/dV|; an inverted chamber's U is NaN, which a line search rejects);
        with_grad: grad += -p dV/dx."""
        self._incremental(x, with_grad, acc, grad)

    @ti.kernel
    def _prepare(self, x: ti.template()):
        gas, volume, bound = ti.static(self.gas, self.volume, self.bound)
        self.chamber_volumes(x)
        ti.loop_config(serialize=ti.static(serial(bound)))
        for c in range(bound.shape[0]):
            bound[c] = 0
            self.block_terms[c] = ti.Vector([gas[c][0] / volume[c] ** 2,
                                      gas[c][0] / volume[c] - gas[c][1]])
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            self.x_at[p] = x[p]
            g = self.volume_gradient(p, x)
            self.grad_v[p] = g
            c = self.chamber_of(p)
            if c >= 0:
                bound[c] += ti.cast(g.norm(), ti.f64)

    def prepare_blocks(self, x, x0, h):
        """k, p, g and S at x, for ``diagonal_block`` and ``add_product``."""
        self._prepare(x)

    @ti.func
    def diagonal_block(self, p):
        """The Hessian's diagonal block k g_p g_p^T, or with ``jacobi`` its bound
        k S |g_p| n_p n_p^T (module docstring)."""
        block = ti.Matrix.zero(float, 3, 3)
        c = self.chamber_of(p)
        g = self.grad_v[p]
        length = g.norm()
        if c >= 0 and length > 0.0:
            weight = self.block_terms[c][0]
            if ti.static(self.jacobi):
                weight *= self.bound[c] / length
            block = ti.cast(weight, float) * g.outer_product(g)
        return block

    @ti.kernel
    def _product(self, v: ti.template(), out: ti.template(), first: ti.template(),
                 whole: ti.template()):
        """out += (= when ``first``) the product with v of the rank-one part k g g^T at the
        prepared x, and unless ``whole`` less ``diagonal_block`` and, with ``exact``, with
        the area-normal part -p d2V v."""
        dot = ti.static(self.dot)
        ti.loop_config(serialize=ti.static(serial(dot)))
        for c in range(dot.shape[0]):
            dot[c] = 0
        ti.loop_config(serialize=ti.static(serial(out)))
        for p in range(out.shape[0]):
            c = self.chamber_of(p)
            if c >= 0:
                dot[c] += ti.cast(self.grad_v[p].dot(v[p]), ti.f64)
        ti.loop_config(serialize=ti.static(serial(out)))
        for p in range(out.shape[0]):
            coupled = ti.Vector.zero(float, 3)
            c = self.chamber_of(p)
            if c >= 0:
                coupled = ti.cast(self.block_terms[c][0] * dot[c], float) * self.grad_v[p]
                if ti.static(not whole):
                    coupled -= self.diagonal_block(p) @ v[p]
                    if ti.static(self.exact):
                        coupled -= ti.cast(self.block_terms[c][1], float) * \
                            self.normal_derivative(p, self.x_at, v)
            add_or_set(out, p, coupled, first)

    def add_product(self, v, out, first):
        """out += (= when ``first``) the Hessian at the prepared x (exact, or its rank-one
        part: ``exact``) less its diagonal blocks (``diagonal_block``), times v."""
        self._product(v, out, first, False)

    def constant_matrix(self):
        """Projective dynamics' stand-in for the Hessian: ``GasStiffness``."""
        return GasStiffness(self)

    # -- XPBD ------------------------------------------------------------------------------
    @ti.func
    def zero_multipliers(self, x):
        """XPBD: no pressure applied yet, and g_s at the substep's start positions x."""
        ti.loop_config(serialize=ti.static(serial(self.lam)))
        for c in range(self.lam.shape[0]):
            self.lam[c] = 0
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            self.grad_start[p] = self.volume_gradient(p, x)

    @ti.func
    def constraint_pass(self, x, x_prev, h):
        """XPBD: one Newton step on each chamber's applied pressure q = p(V(x)) (module
        docstring), from the current x: with w = sum_i w_i g_i . g_s,i (dV/dq = h^2 w),
        dq = (p(V) - q) / (1 + h^2 k w), x_i += h^2 w_i g_s,i dq, q += dq. The gradients
        g_s are those of the substep's start (``zero_multipliers``), not of x_prev."""
        gas, volume, weight = ti.static(self.gas, self.volume, self.weight)
        inv_mass = ti.static(self.inv_mass)
        self.chamber_volumes(x)
        ti.loop_config(serialize=ti.static(serial(weight)))
        for c in range(weight.shape[0]):
            weight[c] = 0
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            c = self.chamber_of(p)
            if c >= 0:
                g = self.volume_gradient(p, x)
                weight[c] += ti.cast(inv_mass[p] * g.dot(self.grad_start[p]), ti.f64)
        ti.loop_config(serialize=ti.static(serial(weight)))
        for c in range(weight.shape[0]):
            v, hh = volume[c], ti.cast(h * h, ti.f64)
            dq = (gas[c][0] / v - gas[c][1] - self.lam[c]) \
                / (1.0 + hh * gas[c][0] / (v * v) * weight[c])
            self.dlam[c] = hh * dq
            self.lam[c] += dq
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            c = self.chamber_of(p)
            if c >= 0:
                x[p] += inv_mass[p] * ti.cast(self.dlam[c], float) * self.grad_start[p]

    @ti.func
    def constraint_pass_in_order(self, x, x_prev, h):
        """``constraint_pass`` inside a batch (the same loops, on its one thread)."""
        self.constraint_pass(x, x_prev, h)


@ti.data_oriented
class GasStiffness(ConstantMatrix):
    """Projective dynamics' stand-in for the gas's Hessian: its rank-one part k0 g0 g0^T at
    the step's start (``update``), positive semi-definite and all of it a coupling of
    CG's products (``diagonal`` 0: projective builds its diagonal once per dt)."""

    def __init__(self, pressure):
        self.pressure = pressure
        self.diagonal = ti.field(runtime.real(), shape=pressure.grad_v.shape[0])

    varies = True

    def update(self, x0):
        """k0 and g0 at the step's start positions x0."""
        self.pressure.prepare_blocks(x0, x0, 0.0)

    def add_product(self, v, out, first):
        """out += (= when ``first``) k0 g0 (g0 . v)."""
        self.pressure._product(v, out, first, True)
