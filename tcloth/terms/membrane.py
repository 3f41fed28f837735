"""Membrane elasticity of a cloth's triangles with separate stretch and shear stiffness:
Baraff & Witkin 1998's stretch and shear conditions, as an energy.

Springs on a mesh's edges cannot do this: a triangle's three edge springs give Poisson's
ratio 1/3 and shear stiffness 3/8 of the stretch (Van Gelder 1998; ``fabric.py``), where
woven fabric shears at a hundredth of its stretch. Each triangle here gets an orthonormal
frame (u, v) in its rest plane, u the warp: the world x axis projected into the plane (the
y axis where the triangle faces x so nearly that x's projection is shorter than 1/2), v =
n x u. With D the 2 x 2 matrix of its rest edges X_1 - X_0, X_2 - X_0 in that frame, the
images of the warp and weft directions are

    f_a = sum_i b_ia x_i,   (b_1; b_2) = the rows of D^-1,   b_0 = -(b_1 + b_2),

unit length and orthogonal at rest and under every rigid motion (the weights b and the
rest areas are the model's, ``features.membrane``). The triangle's energy is

    W = A (C_u/2 (|f_u| - 1)^2 + C_v/2 (|f_v| - 1)^2 + G/2 (f_u . f_v)^2),

A its rest area: stretch along warp and weft as the change of length (linear in it, as the
springs' is) and shear as f_u . f_v, the engineering shear strain at small strain. The three
conditions are uncoupled (Poisson's ratio 0): pulled along the warp with the weft free,
the membrane carries C_u per width per unit strain, and it shears with G, whatever C_u and
C_v are. Each condition c (stiffness k_c) is damped as a spring is along its axis, with
k_d = beta k_c: dissipation beta A sum_c k_c/2 (dc/dt)^2.

The solvers take it as they take the springs. With the energy's gradient in (f_u, f_v),
g_a, a vertex's gradient is sum_a b_ia g_a, and its Hessian in (f_u, f_v) is a 6 x 6 of
3 x 3 blocks, projected to positive semi-definite as the springs' are: a stretch
condition keeps C (n n^T + max(0, 1 - 1/|f|) (I - n n^T)), the shear its Gauss-Newton part
G [f_v; f_u][f_v; f_u]^T (without G (f_u . f_v) I in the coupling block). Backward
Euler's truncated Newton-CG multiplies by the exact Hessian and preconditions with the
projected blocks, as for the springs (``exact``). Backward Euler's
damping is the springs' too: the conditions' rates (dc = grad c(x0) . (x - x0) / h, their
gradients at the step's start) in beta A sum_c k_c h/2 dc^2, whose Hessian is constant
over the step. Projective dynamics keeps A (max(C_u, C_v) + 2 G)(1 + beta/h)
sum_a b_ia b_ja (x) I in its constant matrix (the bound of the Gauss-Newton Hessian at
small strain, rotation invariant as Liu's spring terms are); XPBD takes the three
conditions as constraints with compliances 1 / (A k_c).
"""
import numpy as np
import taichi as ti

from .. import runtime
from ..features.membrane import MEMBRANE
from ..runtime import serial
from .base import ColouredConstraints, ConstantMatrix, Term, add_or_set


@ti.func
def _stretch(f, k, exact: ti.template()):
    """(energy, gradient, Hessian) of k/2 (|f| - 1)^2 in f; the Hessian's transverse part
    k (1 - 1/|f|) clamped at 0 unless ``exact``."""
    length = f.norm()
    n = f / length
    nn = n.outer_product(n)
    tangent = 1.0 - 1.0 / length
    if ti.static(not exact):
        tangent = ti.max(0.0, tangent)
    hessian = k * (nn + tangent * (ti.Matrix.identity(float, 3) - nn))
    return 0.5 * k * (length - 1.0) ** 2, k * (length - 1.0) * n, hessian


@ti.func
def _rates(fu, fv, du, dv):
    """The conditions' rates for changes du, dv of f_u, f_v: the stretches' along f_u, f_v
    and the shear's."""
    return ti.Vector([fu.dot(du) / fu.norm(), fv.dot(dv) / fv.norm(), fv.dot(du) + fu.dot(dv)])


@ti.func
def _weighted(fu, fv, rate, c):
    """The gradient in (f_u, f_v) of sum_c k_c/2 rate_c^2 (rates linear in (du, dv) along
    the conditions' gradients at f_u, f_v; k = the coefficients' first three)."""
    gu = c[0] * rate[0] * fu / fu.norm() + c[2] * rate[2] * fv
    gv = c[1] * rate[1] * fv / fv.norm() + c[2] * rate[2] * fu
    return gu, gv


@ti.func
def _gauss_newton(fu, fv, c, scale):
    """scale times the Hessian in (f_u, f_v) of the conditions linearised at f_u, f_v:
    the blocks (uu, uv, vv) of sum_c k_c grad c grad c^T."""
    nu, nv = fu / fu.norm(), fv / fv.norm()
    uu = scale * (c[0] * nu.outer_product(nu) + c[2] * fv.outer_product(fv))
    vv = scale * (c[1] * nv.outer_product(nv) + c[2] * fu.outer_product(fu))
    uv = scale * c[2] * fv.outer_product(fu)
    return uu, uv, vv


@ti.data_oriented
class Membrane(Term, ColouredConstraints):
    """The triangles of the scene's membrane cloths (``Scene.set_membrane``); for XPBD
    (``constraints=True``) each three constraints (``project_constraint``)."""
    name = "membrane"
    feature = MEMBRANE
    implicit = "potential"
    projective = "force"
    provides = frozenset({"couplings", "local_system", "constant_matrix", "constraints"})
    # exact: ``add_product`` multiplies by the exact Hessian (backward Euler's truncated
    # Newton-CG on exact_hessian), else by the projected one
    options = {"exact": False, "constraints": False}

    @staticmethod
    def present(model):
        return model.membrane is not None and model.membrane.count > 0

    def __init__(self, model, exact=False, constraints=False):
        membrane = model.membrane
        self.tris, self.b, self.c = membrane.triangles, membrane.weights, membrane.coefficients
        self.start, self.entries = membrane.start, membrane.entries
        count, n, real = self.tris.shape[0], model.particle_count, runtime.real()
        # per triangle: the gradient in (f_u, f_v) of the last pass; f and f0 at the
        # Newton iterate and the step's start (``prepare_blocks``, for ``add_product``)
        self.gu, self.gv, self.fu, self.fv, self.f0u, self.f0v = (
            ti.Vector.field(3, real, shape=count) for _ in range(6))
        self.block = ti.Matrix.field(3, 3, real, shape=n)
        self.step = ti.field(real, shape=())
        self.exact = bool(exact)
        if constraints:
            self.inv_mass = model.inv_mass
            self.constraints_begin(self.tris.to_numpy(), n, 3)

    @ti.func
    def project_constraint(self, x, x_prev, h, e):
        """Triangle e's conditions in turn, c_0 = |f_u| - 1, c_1 = |f_v| - 1 and
        c_2 = f_u . f_v, each with compliance 1 / (A k_c) and damping beta k_c (grad_i c =
        b_iu n_u, b_iv n_v and b_iu f_v + b_iv f_u)."""
        ids, b, coef = self.tris[e], self.b[e], self.c[e]
        gamma = coef[3] / h
        for c in ti.static(range(3)):
            fu, fv = self.frame(e, x)
            value, du, dv = fu.dot(fv), fv, fu
            if ti.static(c == 0):
                value, du, dv = fu.norm() - 1.0, fu / fu.norm(), ti.Vector.zero(float, 3)
            elif ti.static(c == 1):
                value, du, dv = fv.norm() - 1.0, ti.Vector.zero(float, 3), fv / fv.norm()
            alpha = 1.0 / (coef[c] * h * h)
            rate, weight = 0.0, 0.0
            for i in ti.static(range(3)):
                grad = b[i, 0] * du + b[i, 1] * dv
                rate += grad.dot(x[ids[i]] - x_prev[ids[i]])
                weight += self.inv_mass[ids[i]] * grad.dot(grad)
            dlam = (-value - alpha * self.lam[e][c] - gamma * rate) \
                / ((1.0 + gamma) * weight + alpha)
            for i in ti.static(range(3)):
                x[ids[i]] += self.inv_mass[ids[i]] * dlam * (b[i, 0] * du + b[i, 1] * dv)
            self.lam[e][c] += dlam

    def batch_obstacle(self):
        if not serial(self.tris):
            return f"the membrane's {self.tris.shape[0]} triangles run on several threads"
        return None

    def coupled_pairs(self):
        """(M,2) particle pairs that share a triangle (for graph colourings), NumPy."""
        ids = self.tris.to_numpy().astype(np.int64)
        return np.concatenate([ids[:, [0, 1]], ids[:, [0, 2]], ids[:, [1, 2]]])

    def constant_matrix(self):
        """Projective dynamics' constant part (module docstring): ``MembraneBound``."""
        return MembraneBound(self)

    @ti.func
    def frame(self, e, x):
        """(f_u, f_v) of triangle e at positions x."""
        ids, b = self.tris[e], self.b[e]
        fu = b[0, 0] * x[ids[0]] + b[1, 0] * x[ids[1]] + b[2, 0] * x[ids[2]]
        fv = b[0, 1] * x[ids[0]] + b[1, 1] * x[ids[1]] + b[2, 1] * x[ids[2]]
        return fu, fv

    @ti.func
    def elastic(self, fu, fv, c):
        """(energy, g_u, g_v): W at f_u, f_v and its gradient."""
        eu, gu, _hu = _stretch(fu, c[0], False)
        ev, gv, _hv = _stretch(fv, c[1], False)
        s = fu.dot(fv)
        return eu + ev + 0.5 * c[2] * s * s, gu + c[2] * s * fv, gv + c[2] * s * fu

    @ti.func
    def hessian(self, fu, fv, c, exact: ti.template()):
        """W's Hessian in (f_u, f_v), blocks (uu, uv, vv): exact, or projected (the
        stretches' transverse parts clamped at 0, the shear's G (f_u . f_v) I dropped)."""
        _eu, _gu, huu = _stretch(fu, c[0], exact)
        _ev, _gv, hvv = _stretch(fv, c[1], exact)
        uv = c[2] * fv.outer_product(fu)
        if ti.static(exact):
            uv += c[2] * fu.dot(fv) * ti.Matrix.identity(float, 3)
        return huu + c[2] * fv.outer_product(fv), uv, hvv + c[2] * fu.outer_product(fu)

    @ti.func
    def gather(self, p):
        """sum over particle p's triangles of b_pa g_a (after a pass that set g): its
        gradient."""
        g = ti.Vector.zero(float, 3)
        for k in range(self.start[p], self.start[p + 1]):
            e, slot = self.entries[k][0], self.entries[k][1]
            g += self.b[e][slot, 0] * self.gu[e] + self.b[e][slot, 1] * self.gv[e]
        return g

    @ti.func
    def triangle_gradient(self, e, x, v):
        """(g_u, g_v): the gradient in (f_u, f_v) of triangle e's energy and damping at
        positions x and velocities v (its corner i's force is -(b_iu g_u + b_iv g_v))."""
        c = self.c[e]
        fu, fv = self.frame(e, x)
        du, dv = self.frame(e, v)
        _, gu, gv = self.elastic(fu, fv, c)
        hu, hv = _weighted(fu, fv, c[3] * _rates(fu, fv, du, dv), c)
        return gu + hu, gv + hv

    @ti.func
    def accumulate(self, x, v, t, f_out):
        """f_out -= the energy's gradient and the damping's, gathered per particle."""
        ti.loop_config(serialize=ti.static(serial(self.tris)))
        for e in range(self.tris.shape[0]):
            self.gu[e], self.gv[e] = self.triangle_gradient(e, x, v)
        ti.loop_config(serialize=ti.static(serial(f_out)))
        for p in range(f_out.shape[0]):
            f_out[p] -= self.gather(p)

    @ti.kernel
    def _sums(self, x: ti.template(), out: ti.template()) -> ti.types.vector(2, ti.f64):
        """[sum over triangles of W, the largest stretch |f_u| - 1 or |f_v| - 1]."""
        out[0] = 0
        out[1] = -1e30
        ti.loop_config(serialize=ti.static(serial(self.tris)))
        for e in range(self.tris.shape[0]):
            fu, fv = self.frame(e, x)
            w, _gu, _gv = self.elastic(fu, fv, self.c[e])
            out[0] += ti.cast(w, out.dtype)
            ti.atomic_max(out[1], ti.cast(ti.max(fu.norm(), fv.norm()) - 1.0, out.dtype))
        return ti.Vector([ti.cast(out[0], ti.f64), ti.cast(out[1], ti.f64)])

    def energy(self, x, t, out):
        """sum over triangles of W, in the accumulator's type."""
        return self.stored(x, t, out)[0]

    def stored(self, x, t, out):
        """(W summed, the largest stretch of a triangle along warp or weft)."""
        values = self._sums(x, out)
        return float(values[0]), float(values[1])

    # -- backward Euler, VBD, projective ------------------------------------------------------
    @ti.func
    def incremental(self, fu, fv, f0u, f0v, c, h):
        """(energy, g_u, g_v) of a triangle's part of the incremental potential, at f_u, f_v
        from f0_u, f0_v at the step's start, coefficients c: W and the damping's
        beta A sum_c k_c h/2 dc^2 with the rates at the step's start."""
        w, gu, gv = self.elastic(fu, fv, c)
        rate = _rates(f0u, f0v, (fu - f0u) / h, (fv - f0v) / h)
        hu, hv = _weighted(f0u, f0v, c[3] * rate, c)
        damping = 0.5 * h * c[3] * (c[0] * rate[0] ** 2 + c[1] * rate[1] ** 2
                                    + c[2] * rate[2] ** 2)
        return w + damping, gu + hu, gv + hv

    @ti.kernel
    def _incremental(self, x: ti.template(), x0: ti.template(), h: float,
                     with_grad: ti.template(), acc: ti.template(), grad: ti.template()):
        ti.loop_config(serialize=ti.static(serial(self.tris)))
        for e in range(self.tris.shape[0]):
            fu, fv = self.frame(e, x)
            f0u, f0v = self.frame(e, x0)
            w, gu, gv = self.incremental(fu, fv, f0u, f0v, self.c[e], h)
            acc[0] += ti.cast(w, acc.dtype)
            acc[1] += ti.cast(w, acc.dtype)
            self.gu[e], self.gv[e] = gu, gv
        if ti.static(with_grad):
            ti.loop_config(serialize=ti.static(serial(grad)))
            for p in range(grad.shape[0]):
                grad[p] += self.gather(p)

    def add_incremental(self, x, x0, h, with_grad, acc, grad):
        """acc[0] += the energy and damping potential at x (acc[1] their magnitude);
        with_grad: grad += their gradient."""
        self._incremental(x, x0, h, with_grad, acc, grad)

    @ti.func
    def blocks(self, fu, fv, f0u, f0v, c, h, exact: ti.template()):
        """The incremental potential's Hessian in (f_u, f_v) of one triangle, exact or
        projected."""
        uu, uv, vv = self.hessian(fu, fv, c, exact)
        du, dv_, dvv = _gauss_newton(f0u, f0v, c, c[3] / h)
        return uu + du, uv + dv_, vv + dvv

    @ti.func
    def vertex_block(self, b, slot, uu, uv, vv):
        bu, bv = b[slot, 0], b[slot, 1]
        return bu * bu * uu + bu * bv * (uv + uv.transpose()) + bv * bv * vv

    @ti.kernel
    def _prepare(self, x: ti.template(), x0: ti.template(), h: float):
        self.step[None] = h
        ti.loop_config(serialize=ti.static(serial(self.tris)))
        for e in range(self.tris.shape[0]):
            self.fu[e], self.fv[e] = self.frame(e, x)
            self.f0u[e], self.f0v[e] = self.frame(e, x0)
        ti.loop_config(serialize=ti.static(serial(self.block)))
        for p in range(self.block.shape[0]):
            block = ti.Matrix.zero(float, 3, 3)
            for k in range(self.start[p], self.start[p + 1]):
                e, slot = self.entries[k][0], self.entries[k][1]
                uu, uv, vv = self.blocks(self.fu[e], self.fv[e], self.f0u[e], self.f0v[e],
                                         self.c[e], h, False)
                block += self.vertex_block(self.b[e], slot, uu, uv, vv)
            self.block[p] = block

    def prepare_blocks(self, x, x0, h):
        """The Hessian at x (for ``diagonal_block``, projected, and ``add_product``)."""
        self._prepare(x, x0, h)

    @ti.func
    def diagonal_block(self, p):
        return self.block[p]

    @ti.kernel
    def _couplings(self, v: ti.template(), out: ti.template(), first: ti.template()):
        h = self.step[None]
        ti.loop_config(serialize=ti.static(serial(self.tris)))
        for e in range(self.tris.shape[0]):
            uu, uv, vv = self.blocks(self.fu[e], self.fv[e], self.f0u[e], self.f0v[e],
                                     self.c[e], h, ti.static(self.exact))
            du, dv = self.frame(e, v)
            self.gu[e] = uu @ du + uv @ dv
            self.gv[e] = uv.transpose() @ du + vv @ dv
        ti.loop_config(serialize=ti.static(serial(out)))
        for p in range(out.shape[0]):
            add_or_set(out, p, self.gather(p) - self.block[p] @ v[p], first)

    def add_product(self, v, out, first):
        """out += (= when ``first``) the Hessian at the prepared x (exact or projected,
        ``exact``) less its projected diagonal blocks (``diagonal_block``), times v."""
        self._couplings(v, out, first)

    @ti.func
    def local_system(self, p, x, x0, h):
        """(gradient, projected Hessian block) of particle p at x, its triangles evaluated
        afresh (VBD's Gauss-Seidel sweeps move its neighbours between calls)."""
        g = ti.Vector.zero(float, 3)
        block = ti.Matrix.zero(float, 3, 3)
        for k in range(self.start[p], self.start[p + 1]):
            e, slot = self.entries[k][0], self.entries[k][1]
            b, c = self.b[e], self.c[e]
            fu, fv = self.frame(e, x)
            f0u, f0v = self.frame(e, x0)
            _, gu, gv = self.incremental(fu, fv, f0u, f0v, c, h)
            g += b[slot, 0] * gu + b[slot, 1] * gv
            uu, uv, vv = self.blocks(fu, fv, f0u, f0v, c, h, False)
            block += self.vertex_block(b, slot, uu, uv, vv)
        return g, block

    @ti.func
    def local_energy(self, p, x, x0, h):
        """The energy and damping potential of particle p's triangles at x (as a function
        of x[p] alone, the incremental potential's part up to a constant)."""
        e = 0.0
        for k in range(self.start[p], self.start[p + 1]):
            tri = self.entries[k][0]
            fu, fv = self.frame(tri, x)
            f0u, f0v = self.frame(tri, x0)
            w, _gu, _gv = self.incremental(fu, fv, f0u, f0v, self.c[tri], h)
            e += w
        return e


@ti.data_oriented
class MembraneBound(ConstantMatrix):
    """Projective dynamics' constant stand-in for the membrane's Hessian:
    A (max(C_u, C_v) + 2 G)(1 + beta / h) sum_a b_ia b_ja (x) I per triangle (``set_step``
    before use), as a scalar ``diagonal`` per particle and its couplings' product."""

    def __init__(self, membrane):
        self.m = membrane
        n, count, real = membrane.block.shape[0], membrane.tris.shape[0], runtime.real()
        self.diagonal = ti.field(real, shape=n)
        self.weight = ti.field(real, shape=count)
        self.sum_u, self.sum_v = (ti.Vector.field(3, real, shape=count) for _ in range(2))

    @ti.kernel
    def set_step(self, h: float):
        m = self.m
        for e in range(m.tris.shape[0]):
            c = m.c[e]
            self.weight[e] = (ti.max(c[0], c[1]) + 2.0 * c[2]) * (1.0 + c[3] / h)
        for p in range(self.diagonal.shape[0]):
            d = 0.0
            for k in range(m.start[p], m.start[p + 1]):
                e, slot = m.entries[k][0], m.entries[k][1]
                d += self.weight[e] * (m.b[e][slot, 0] ** 2 + m.b[e][slot, 1] ** 2)
            self.diagonal[p] = d

    @ti.kernel
    def _couplings(self, v: ti.template(), out: ti.template(), first: ti.template()):
        m = self.m
        ti.loop_config(serialize=ti.static(serial(m.tris)))
        for e in range(m.tris.shape[0]):
            du, dv = m.frame(e, v)
            self.sum_u[e], self.sum_v[e] = self.weight[e] * du, self.weight[e] * dv
        ti.loop_config(serialize=ti.static(serial(out)))
        for p in range(out.shape[0]):
            coupled = -self.diagonal[p] * v[p]
            for k in range(m.start[p], m.start[p + 1]):
                e, slot = m.entries[k][0], m.entries[k][1]
                coupled += m.b[e][slot, 0] * self.sum_u[e] + m.b[e][slot, 1] * self.sum_v[e]
            add_or_set(out, p, coupled, first)

    def add_product(self, v, out, first):
        """out += (= when ``first``) the stand-in without its diagonal, times v."""
        self._couplings(v, out, first)
