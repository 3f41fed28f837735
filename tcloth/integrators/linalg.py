"""Vector kernels and a filtered, Jacobi-preconditioned conjugate-gradient solver
shared by the implicit integrators. Vectors are Taichi fields of vec3 over particles;
particles with inverse mass 0 (pinned) are filtered out: their entries are left as they are."""
import numpy as np
import taichi as ti

from .. import runtime
from ..runtime import serial


@ti.kernel
def dot(a: ti.template(), b: ti.template()) -> ti.f64:
    total = ti.cast(0.0, ti.f64)
    ti.loop_config(serialize=ti.static(serial(a)))
    for p in range(a.shape[0]):
        total += ti.cast(a[p].dot(b[p]), ti.f64)
    return total


@ti.kernel
def max_norm(a: ti.template()) -> ti.f64:
    best = ti.cast(0.0, ti.f64)
    ti.loop_config(serialize=ti.static(serial(a)))
    for p in range(a.shape[0]):
        ti.atomic_max(best, ti.cast(a[p].norm(), ti.f64))
    return best


@ti.kernel
def axpy_into(out: ti.template(), x: ti.template(), alpha: float, d: ti.template()):
    """out = x + alpha d (out may be x)."""
    ti.loop_config(serialize=ti.static(serial(out)))
    for p in range(out.shape[0]):
        out[p] = x[p] + alpha * d[p]


@ti.func
def copy(out, a):
    """out = a (fields of one shape, any number of dimensions)."""
    ti.loop_config(serialize=ti.static(runtime.serial_count(int(np.prod(out.shape)))))
    for I in ti.grouped(ti.ndrange(*out.shape)):     # a range-for: serialize applies
        out[I] = a[I]


@ti.kernel
def copy_into(out: ti.template(), a: ti.template()):
    copy(out, a)


@ti.kernel
def extrapolate_into(out: ti.template(), a: ti.template(), alpha: float, b: ti.template()):
    """out = a + alpha (b - a): where the move from a to b, taken alpha times, ends."""
    ti.loop_config(serialize=ti.static(serial(out)))
    for p in range(out.shape[0]):
        out[p] = a[p] + alpha * (b[p] - a[p])


@ti.kernel
def scale_into(out: ti.template(), alpha: float, d: ti.template()):
    """out = alpha d."""
    ti.loop_config(serialize=ti.static(serial(out)))
    for p in range(out.shape[0]):
        out[p] = alpha * d[p]


def _is_matrix(field):
    return isinstance(field, ti.MatrixField) and field.m == 3


def _is_symmetric(field):
    return isinstance(field, ti.MatrixField) and field.n == 6 and field.m == 1


@ti.func
def symmetric6(a):
    """A symmetric 3x3 matrix stored as (xx, yy, zz, xy, xz, yz)."""
    return ti.Vector([a[0, 0], a[1, 1], a[2, 2], a[0, 1], a[0, 2], a[1, 2]])


@ti.func
def unpack6(a):
    """The 3x3 matrix of a ``symmetric6`` vector."""
    return ti.Matrix([[a[0], a[3], a[4]], [a[3], a[1], a[5]], [a[4], a[5], a[2]]])


@ti.func
def symmetric6_times(a, v):
    """A v for A given as ``symmetric6``."""
    return ti.Vector([a[0] * v[0] + a[3] * v[1] + a[4] * v[2],
                      a[3] * v[0] + a[1] * v[1] + a[5] * v[2],
                      a[4] * v[0] + a[5] * v[1] + a[2] * v[2]])


@ti.func
def _apply(field: ti.template(), p, v):
    """field[p] v: a 3x3 block, a symmetric block (``symmetric6``) or a scalar times v."""
    out = v
    if ti.static(_is_matrix(field)):
        out = field[p] @ v
    elif ti.static(_is_symmetric(field)):
        out = symmetric6_times(field[p], v)
    else:
        out = field[p] * v
    return out


class ConjugateGradients:
    """The iteration loop of a conjugate-gradient solver whose kernels ``_start`` (set up
    from x = 0, return r.r; ``_begin`` calls it, or another start) and ``_iterate`` (one
    iteration, return r.r, or -1 when the matrix is not positive definite along the
    search direction p, leaving x as it was) are given by a subclass, with fields ``x``
    and ``p``, and ``precondition`` (x = the preconditioner applied to b)."""

    def solve(self, tol, max_iterations):
        """Iterate from x = 0 until the residual has dropped to tol times |b| or
        max_iterations. Returns (iterations, relative residual). On an indefinite matrix
        CG stops at the first direction of non-positive curvature, with x as it was, or
        at the first iteration with x = p, the preconditioned right-hand side (truncated
        CG as in Newton-CG, Nocedal & Wright, Numerical Optimization, Algorithm 7.1): for a
        Newton step on E, with b = -grad E, x is then still a descent direction (of any
        length: near-zero positive curvature before the negative one can make it huge;
        ``precondition`` gives a bounded one)."""
        r0 = np.sqrt(self._begin())
        if r0 == 0.0:
            return 0, 0.0
        k, rel = 0, 1.0
        while k < max_iterations and rel >= tol:
            k += 1
            rr = self._iterate()
            if rr < 0.0:
                if k == 1:
                    copy_into(self.x, self.p)
                break
            rel = np.sqrt(rr) / r0
        return k, rel

    def _begin(self):
        """Set up the iterations (``_start``); returns b.b."""
        return self._start()


@ti.data_oriented
class PCG(ConjugateGradients):
    """Filtered, Jacobi-preconditioned conjugate gradients on A x = b, A given per particle:

        (A v)_p = D_p v_p + sum over p's adjacency entries k = (s, q) of W_k (v_p - v_q)

    with diag D (per particle) and weights W (per adjacency entry: both ends of a spring
    carry the same coupling, stored twice so that the gather reads them in order) 3x3
    blocks, symmetric blocks (``symmetric6``) or scalars, gathered per particle (no
    atomics), and ``precond`` the inverse diagonal of A (blocks or scalars). Particles
    with inverse mass 0 are filtered out: their entries of x stay as they are. The operands
    are this object's fields ``b`` and ``x``, and every kernel reads the fields the solver
    was built with, so that a CG iteration is one kernel launch without field arguments
    (each costs Python time).

    ``couplings``: objects whose ``add_product(v, out, first)`` adds to out (sets it, when
    ``first``) the product of a further, matrix-free part of A with v (couplings that the
    adjacency does not hold, such as self-contacts); each costs a launch per iteration."""

    def __init__(self, n, diag, weights, adj_start, adj, precond, inv_mass, couplings=()):
        real = runtime.real()
        self.diag, self.weights, self.adj_start, self.adj = diag, weights, adj_start, adj
        self.precond, self.inv_mass = precond, inv_mass
        self.x, self.b, self.r, self.z, self.p, self.ap = (
            ti.Vector.field(3, real, shape=n) for _ in range(6))
        self.scalars = ti.field(ti.f64, shape=3)     # r.z, p.Ap, the next r.z
        self.couplings = tuple(couplings)
        self.coupled = bool(self.couplings)
        self.extra = ti.Vector.field(3, real, shape=n if self.coupled else 1)

    def _couple(self, v):
        """extra = the couplings' product with v."""
        for k, coupling in enumerate(self.couplings):
            coupling.add_product(v, self.extra, k == 0)

    @ti.func
    def _product(self, v: ti.template(), p):
        """(A v)_p (the couplings' part read from ``extra``, computed beforehand)."""
        vp = v[p]
        acc = _apply(self.diag, p, vp)
        for k in range(self.adj_start[p], self.adj_start[p + 1]):
            acc += _apply(self.weights, k, vp - v[self.adj[k][1]])
        if ti.static(self.coupled):
            acc += self.extra[p]
        return acc

    def apply(self, v, out):
        """out = A v (for tests and tools)."""
        self._couple(v)
        self._multiply(v, out)

    @ti.kernel
    def _multiply(self, v: ti.template(), out: ti.template()):
        for p in range(out.shape[0]):
            out[p] = self._product(v, p)

    def _iterate(self):
        self._couple(self.p)
        return self._iteration()

    def precondition(self):
        """x = P^-1 b on free particles (0 on pinned ones)."""
        self._start()
        copy_into(self.x, self.p)

    @ti.func
    def _precondition_r(self):
        """z = P^-1 r (0 on pinned particles, whose r is 0); returns r.z. A subclass may
        precondition otherwise (``multigrid.MultigridPCG``: a V-cycle)."""
        rz = ti.cast(0.0, ti.f64)
        ti.loop_config(serialize=ti.static(serial(self.x)))
        for p in range(self.x.shape[0]):
            zp = ti.Vector.zero(float, 3)
            if self.inv_mass[p] > 0.0:
                zp = _apply(self.precond, p, self.r[p])
            self.z[p] = zp
            rz += ti.cast(self.r[p].dot(zp), ti.f64)
        return rz

    @ti.kernel
    def _start(self) -> ti.f64:
        """x = 0, r = b, z = p = P^-1 r on free particles, 0 on pinned ones;
        scalars[0] = r.z. Returns r.r."""
        rr = ti.cast(0.0, ti.f64)
        ti.loop_config(serialize=ti.static(serial(self.x)))
        for p in range(self.x.shape[0]):
            rp = ti.Vector.zero(float, 3)
            if self.inv_mass[p] > 0.0:
                rp = self.b[p]
            self.x[p] = ti.Vector.zero(float, 3)
            self.r[p] = rp
            rr += ti.cast(rp.dot(rp), ti.f64)
        self._first_direction()
        return rr

    @ti.func
    def _first_direction(self):
        """z = p = P^-1 r; scalars[0] = r.z (the start's, after r is set)."""
        self.scalars[0] = self._precondition_r()
        ti.loop_config(serialize=ti.static(serial(self.x)))
        for p in range(self.x.shape[0]):
            self.p[p] = self.z[p]

    @ti.kernel
    def _iteration(self) -> ti.f64:
        """One CG iteration: Ap; alpha = r.z / p.Ap; x += alpha p; r -= alpha Ap;
        z = P^-1 r; p = z + beta p. Returns r.r, or -1 when p.Ap <= 0 (A not positive
        definite along p: x and r are left unchanged)."""
        self.scalars[1] = 0.0
        ti.loop_config(serialize=ti.static(serial(self.x)))
        for p in range(self.x.shape[0]):
            ap = self._product(self.p, p)
            self.ap[p] = ap
            if self.inv_mass[p] > 0.0:
                self.scalars[1] += ti.cast(self.p[p].dot(ap), ti.f64)
        rr = ti.cast(0.0, ti.f64)
        ti.loop_config(serialize=ti.static(serial(self.x)))
        for p in range(self.x.shape[0]):
            if self.inv_mass[p] > 0.0 and self.scalars[1] > 0.0:
                alpha = ti.cast(self.scalars[0] / self.scalars[1], float)
                self.x[p] += alpha * self.p[p]
                self.r[p] -= alpha * self.ap[p]
                rr += ti.cast(self.r[p].dot(self.r[p]), ti.f64)
        self.scalars[2] = self._precondition_r()
        ti.loop_config(serialize=ti.static(serial(self.x)))
        for p in range(self.x.shape[0]):
            if self.scalars[0] > 0.0 and self.scalars[1] > 0.0:
                beta = ti.cast(self.scalars[2] / self.scalars[0], float)
                self.p[p] = self.z[p] + beta * self.p[p]
        if self.scalars[1] <= 0.0:
            rr = -1.0
        self.scalars[0] = self.scalars[2]
        return rr
