"""Force evaluation: gravity, viscous air drag and springs.

``compute_forces(model, x, v, f_out)`` fills the force accumulator ``f_out`` at the state
(x, v). Only the terms the scene has are launched: no springs, no spring kernel; a cloth
grid is one stencil launch per cloth, with families absent from the cloth compiled out.
"""
import taichi as ti

from .runtime import serial

# Grid stencil offsets (di, dj) of each Provot family: every spring a particle takes part in.
STRUCTURAL = ((1, 0), (-1, 0), (0, 1), (0, -1))
SHEAR = ((1, 1), (-1, -1), (1, -1), (-1, 1))
FLEXION = ((2, 0), (-2, 0), (0, 2), (0, -2))


@ti.func
def spring_force(xi, xj, vi, vj, ks, kd, rest):
    """Force on particle i from spring (i, j): -(k_s (|x_ij| - l0) + k_d v_ij . d) d,
    d = x_ij / |x_ij| (lecture 4). Coincident ends give no force (direction undefined)."""
    d = xi - xj
    length = d.norm()
    n = d / ti.max(length, 1e-30)
    return -(ks * (length - rest) + kd * (vi - vj).dot(n)) * n


@ti.kernel
def init_forces(v: ti.template(), mass: ti.template(), gravity: ti.math.vec3, drag: float,
                f_out: ti.template()):
    """f = m g - c v: gravity and viscous air drag."""
    ti.loop_config(serialize=ti.static(serial(f_out)))
    for p in range(f_out.shape[0]):
        f_out[p] = mass[p] * gravity - drag * v[p]


@ti.kernel
def eval_springs(x: ti.template(), v: ti.template(), pairs: ti.template(), ks: ti.template(),
                 kd: ti.template(), rest: ti.template(), count: ti.i32, f_out: ti.template()):
    """Springs from a list: equal and opposite forces on both ends (atomic adds)."""
    ti.loop_config(serialize=ti.static(serial(pairs)))
    for s in range(count):
        i, j = pairs[s][0], pairs[s][1]
        fi = spring_force(x[i], x[j], v[i], v[j], ks[s], kd[s], rest[s])
        f_out[i] += fi
        f_out[j] -= fi


@ti.func
def _stencil_sum(x, v, offset, nx, ny, i, j, xp, vp, ks, kd, dx, dy, stencil: ti.template()):
    acc = ti.Vector.zero(float, 3)
    for k in ti.static(range(len(stencil))):
        di, dj = ti.static(stencil[k][0], stencil[k][1])
        ii, jj = i + di, j + dj
        if 0 <= ii < nx and 0 <= jj < ny:
            q = offset + jj * nx + ii
            rest = ti.sqrt((di * dx) ** 2 + (dj * dy) ** 2)
            acc += spring_force(xp, x[q], vp, v[q], ks, kd, rest)
    return acc


@ti.kernel
def eval_grid_springs(x: ti.template(), v: ti.template(), offset: ti.i32, nx: ti.i32,
                      ny: ti.i32, dx: float, dy: float, params: ti.math.vec3,
                      params_b: ti.math.vec3, families: ti.template(), f_out: ti.template()):
    """Provot springs of one regular cloth grid, gathered per particle (no atomics).

    params = (k_s structural, k_s shear, k_s flexion), params_b the matching k_d.
    families: static tuple of booleans (structural, shear, flexion).
    """
    ti.loop_config(serialize=ti.static(serial(f_out)))
    for j, i in ti.ndrange(ny, nx):
        p = offset + j * nx + i
        xp, vp = x[p], v[p]
        acc = ti.Vector.zero(float, 3)
        if ti.static(families[0]):
            acc += _stencil_sum(x, v, offset, nx, ny, i, j, xp, vp, params[0], params_b[0],
                                dx, dy, STRUCTURAL)
        if ti.static(families[1]):
            acc += _stencil_sum(x, v, offset, nx, ny, i, j, xp, vp, params[1], params_b[1],
                                dx, dy, SHEAR)
        if ti.static(families[2]):
            acc += _stencil_sum(x, v, offset, nx, ny, i, j, xp, vp, params[2], params_b[2],
                                dx, dy, FLEXION)
        f_out[p] += acc


def _grid_args(g):
    fams = (g.structural, g.shear, g.flexion)
    ks = [0.0 if p is None else p[0] for p in fams]
    kd = [0.0 if p is None else p[1] for p in fams]
    return ks, kd, tuple(p is not None for p in fams)


def compute_forces(model, x, v, f_out):
    """Total force on every particle at positions x and velocities v, into f_out (N)."""
    init_forces(v, model.mass, model.gravity.tolist(), model.air_drag, f_out)
    for g in model.grids:
        ks, kd, fams = _grid_args(g)
        if any(fams):
            eval_grid_springs(x, v, g.offset, g.nx, g.ny, g.dx, g.dy, ks, kd, fams, f_out)
    if model.list_spring_count:
        eval_springs(x, v, model.spring_pairs, model.spring_ks, model.spring_kd,
                     model.spring_rest, model.list_spring_count, f_out)
