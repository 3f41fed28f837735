"""Vector kernels and a filtered, block-Jacobi preconditioned conjugate-gradient solver
shared by the implicit integrators. Vectors are Taichi fields of vec3 over particles;
particles with inverse mass 0 (pinned) are filtered out: their entries stay 0."""
import numpy as np
import taichi as ti

from .. import runtime
from ..runtime import serial


class Work:
    """CG work vectors (r, z, p, Ap) for n particles."""

    def __init__(self, n):
        self.r, self.z, self.p, self.ap = (ti.Vector.field(3, runtime.real(), shape=n)
                                           for _ in range(4))


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


@ti.kernel
def scale_into(out: ti.template(), alpha: float, d: ti.template()):
    """out = alpha d."""
    ti.loop_config(serialize=ti.static(serial(out)))
    for p in range(out.shape[0]):
        out[p] = alpha * d[p]


@ti.kernel
def _residual(inv_mass: ti.template(), b: ti.template(), ax: ti.template(), r: ti.template()):
    """r = b - A x on free particles, 0 on pinned ones."""
    ti.loop_config(serialize=ti.static(serial(r)))
    for p in range(r.shape[0]):
        r[p] = ti.Vector.zero(float, 3)
        if inv_mass[p] > 0.0:
            r[p] = b[p] - ax[p]


@ti.kernel
def _apply_precond(precond: ti.template(), inv_mass: ti.template(), r: ti.template(),
                   z: ti.template(), p_dir: ti.template(), first: ti.template()) -> ti.f64:
    """z = P^-1 r (filtered); on the first iteration also p = z. Returns r . z."""
    rz = ti.cast(0.0, ti.f64)
    ti.loop_config(serialize=ti.static(serial(r)))
    for p in range(r.shape[0]):
        zp = precond[p] @ r[p] if inv_mass[p] > 0.0 else ti.Vector.zero(float, 3)
        z[p] = zp
        if ti.static(first):
            p_dir[p] = zp
        rz += ti.cast(r[p].dot(zp), ti.f64)
    return rz


@ti.kernel
def _cg_update(inv_mass: ti.template(), alpha: float, p_dir: ti.template(),
               ap: ti.template(), x: ti.template(), r: ti.template()) -> ti.f64:
    """x += alpha p; r -= alpha A p on free particles. Returns r . r."""
    rr = ti.cast(0.0, ti.f64)
    ti.loop_config(serialize=ti.static(serial(r)))
    for p in range(r.shape[0]):
        if inv_mass[p] > 0.0:
            x[p] += alpha * p_dir[p]
            r[p] -= alpha * ap[p]
            rr += ti.cast(r[p].dot(r[p]), ti.f64)
    return rr


@ti.kernel
def _cg_direction(beta: float, z: ti.template(), p_dir: ti.template()):
    ti.loop_config(serialize=ti.static(serial(z)))
    for p in range(z.shape[0]):
        p_dir[p] = z[p] + beta * p_dir[p]


def pcg(matvec, precond, inv_mass, b, x, work, tol, max_iterations, warm_start=False):
    """Solve A x = b for the free particles by preconditioned conjugate gradients.

    matvec(p, out): out = A p. precond: field of 3x3 blocks, the inverse block diagonal.
    warm_start: start from x as given (else from 0). Stops when the residual has dropped
    to tol times the starting one (|b| from 0; with a warm start |b| can dwarf the part of
    the solution still missing). Returns (iterations, relative residual).
    """
    if warm_start:
        matvec(x, work.ap)
    else:
        x.fill(0)
        work.ap.fill(0)
    _residual(inv_mass, b, work.ap, work.r)
    r0 = np.sqrt(dot(work.r, work.r))
    if r0 == 0.0:
        return 0, 0.0
    rz = _apply_precond(precond, inv_mass, work.r, work.z, work.p, True)
    k, rel = 0, 1.0
    while k < max_iterations:
        k += 1
        matvec(work.p, work.ap)
        pap = dot(work.p, work.ap)
        if pap <= 0.0:
            break
        rel = np.sqrt(_cg_update(inv_mass, rz / pap, work.p, work.ap, x, work.r)) / r0
        if rel < tol:
            break
        rz_new = _apply_precond(precond, inv_mass, work.r, work.z, work.p, False)
        _cg_direction(rz_new / rz, work.z, work.p)
        rz = rz_new
    return k, rel
