"""Force evaluation: gravity, viscous air drag, springs, wind, attraction and contacts.

``compute_forces(model, x, v, f_out)`` fills the force accumulator ``f_out`` at the state
(x, v). Only the terms the scene has are launched: no springs, no spring kernel; a cloth
grid is one stencil launch per cloth, with families absent from the cloth compiled out.
"""
import taichi as ti

from .colliders import collide
from .runtime import cpu, serial
from .scene import wind_velocity

# Grid springs by family: the two a particle (i, j) owns, to (i + di, j + dj); with the
# two owned by (i - di, j - dj) these are the four springs of each family at a particle.
OWNED = (((1, 0), (0, 1)),       # structural
         ((1, 1), (-1, 1)),      # shear
         ((2, 0), (0, 2)))       # flexion


@ti.func
def spring_force(xi, xj, vi, vj, ks, kd, rest):
    """Force on particle i from spring (i, j): -(k_s (|x_ij| - l0) + k_d v_ij . d) d,
    d = x_ij / |x_ij| (lecture 4). Coincident ends give no force (direction undefined)."""
    d = xi - xj
    length = d.norm()
    n = d * (1.0 / ti.max(length, 1e-30))
    return -(ks * (length - rest) + kd * (vi - vj).dot(n)) * n


@ti.func
def body_force(mass, params, v, p):
    """m g - c v on particle p: gravity and viscous air drag; params = (g_x, g_y, g_z, c)."""
    return mass[p] * ti.Vector([params[0], params[1], params[2]]) - params[3] * v[p]


@ti.kernel
def init_forces(v: ti.template(), mass: ti.template(), params: ti.template(),
                f_out: ti.template()):
    """f = ``body_force`` for every particle."""
    ti.loop_config(serialize=ti.static(serial(f_out)))
    for p in range(f_out.shape[0]):
        f_out[p] = body_force(mass, params, v, p)


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
def _owned_springs(x, v, offset, nx, ny, i, j, g, rest, families: ti.template(),
                   grid_forces):
    """Forces of the springs particle (i, j) owns, on it, into grid_forces[p, slot]
    (slot = 2 family + s); 0 where the other end is off the grid."""
    if 1 <= i < nx - 2 and j < ny - 2:     # no owned spring can leave the grid
        _owned_springs_checked(x, v, offset, nx, ny, i, j, g, rest, families, grid_forces,
                               False)
    else:
        _owned_springs_checked(x, v, offset, nx, ny, i, j, g, rest, families, grid_forces,
                               True)


@ti.func
def _owned_springs_checked(x, v, offset, nx, ny, i, j, g, rest, families: ti.template(),
                           grid_forces, checked: ti.template()):
    """``_owned_springs``; checked: test that each spring's other end exists."""
    p = offset + j * nx + i
    xp, vp = x[p], v[p]
    for fam in ti.static(range(3)):
        if ti.static(families[fam]):
            for s in ti.static(range(2)):
                di, dj = ti.static(OWNED[fam][s][0], OWNED[fam][s][1])
                ii, jj = i + di, j + dj
                force = ti.Vector.zero(float, 3)
                if ti.static(not checked) or (0 <= ii < nx and 0 <= jj < ny):
                    q = offset + jj * nx + ii
                    force = spring_force(xp, x[q], vp, v[q], g[2 + fam], g[5 + fam],
                                         rest_length(rest, di, dj))
                grid_forces[p, 2 * fam + s] = force


@ti.func
def grid_spring_sum(offset, nx, ny, i, j, families: ti.template(), grid_forces):
    """The spring force on particle (i, j) of a grid after ``owned_grid_springs``: its own
    springs' forces minus those its neighbours own with it."""
    p = offset + j * nx + i
    acc = ti.Vector.zero(float, 3)
    for fam in ti.static(range(3)):
        if ti.static(families[fam]):
            for s in ti.static(range(2)):
                di, dj = ti.static(OWNED[fam][s][0], OWNED[fam][s][1])
                acc += grid_forces[p, 2 * fam + s]
                ii, jj = i - di, j - dj
                if 0 <= ii < nx and 0 <= jj < ny:
                    acc -= grid_forces[offset + jj * nx + ii, 2 * fam + s]
    return acc


@ti.func
def grid_rest_lengths(g):
    """The grid's cell sides and diagonal from its grid_reals row g (``rest_length``)."""
    dx, dy = g[0], g[1]
    return ti.Vector([dx, dy, ti.sqrt(dx * dx + dy * dy)])


@ti.func
def rest_length(rest, di: ti.template(), dj: ti.template()):
    """The rest length of the grid spring to offset (di, dj) from ``grid_rest_lengths``:
    a cell diagonal (shear), or one or two cell sides (structural, flexion)."""
    length = rest[2]
    if ti.static(dj == 0):
        length = ti.static(abs(di)) * rest[0]
    elif ti.static(di == 0):
        length = ti.static(abs(dj)) * rest[1]
    return length


@ti.func
def owned_grid_springs(x, v, offset, nx, ny, g, families: ti.template(), grid_forces):
    """A loop over the grid: the forces of the springs each particle owns (``OWNED``)
    into grid_forces[p, 2 family + s]. g: the grid's grid_reals row.

    On CPUs rows in parallel and the particles of a row in order (no index division per
    particle); elsewhere every particle in parallel."""
    rest = grid_rest_lengths(g)
    if ti.static(cpu()):
        ti.loop_config(serialize=ti.static(serial(grid_forces)))
        for j in range(ny):
            for i in range(nx):
                _owned_springs(x, v, offset, nx, ny, i, j, g, rest, families, grid_forces)
    else:
        for j, i in ti.ndrange(ny, nx):
            _owned_springs(x, v, offset, nx, ny, i, j, g, rest, families, grid_forces)


@ti.func
def _gather_grid(v, offset, nx, ny, i, j, families: ti.template(), mass, params,
                 first: ti.template(), grid_forces, f_out):
    p = offset + j * nx + i
    acc = grid_spring_sum(offset, nx, ny, i, j, families, grid_forces)
    if ti.static(first):
        f_out[p] = body_force(mass, params, v, p) + acc
    else:
        f_out[p] += acc


@ti.kernel
def eval_grid_springs(x: ti.template(), v: ti.template(), grid_ints: ti.template(),
                      grid_reals: ti.template(), k: ti.i32, families: ti.template(),
                      mass: ti.template(), params: ti.template(), first: ti.template(),
                      grid_forces: ti.template(), f_out: ti.template()):
    """Provot springs of cloth grid k, each evaluated once and gathered per particle (no
    atomics): every particle computes the springs it owns (``OWNED``) into grid_forces,
    then adds those and subtracts the ones its neighbours own with it.

    grid_ints[k] = (offset, nx, ny); grid_reals[k] = (dx, dy, k_s structural, k_s shear,
    k_s flexion, k_d structural, k_d shear, k_d flexion).
    families: static tuple of booleans (structural, shear, flexion).
    first: the grid holds every particle and comes first: f = gravity and drag (as in
    ``init_forces``) + springs, saving a launch and a pass; else f += springs.
    grid_forces: (particles, 6) vec3 scratch.
    """
    offset, nx, ny = grid_ints[k][0], grid_ints[k][1], grid_ints[k][2]
    owned_grid_springs(x, v, offset, nx, ny, grid_reals[k], families, grid_forces)
    if ti.static(cpu()):
        ti.loop_config(serialize=ti.static(serial(f_out)))
        for j in range(ny):
            for i in range(nx):
                _gather_grid(v, offset, nx, ny, i, j, families, mass, params, first,
                             grid_forces, f_out)
    else:
        for j, i in ti.ndrange(ny, nx):
            _gather_grid(v, offset, nx, ny, i, j, families, mass, params, first,
                         grid_forces, f_out)


@ti.kernel
def eval_wind(x: ti.template(), v: ti.template(), triangles: ti.template(),
              params: ti.template(), t: float, f_out: ti.template()):
    """Wejchert & Haumann quadratic wind on every triangle, a third to each particle.

    params = (velocity (3), gust amplitude (3), frequency, phase, drag, lift, tangential).
    """
    wind = ti.Vector([params[0], params[1], params[2]]) + ti.Vector(
        [params[3], params[4], params[5]]) * ti.sin(2.0 * 3.141592653589793 * params[6] * t
                                                    + params[7])
    ti.loop_config(serialize=ti.static(serial(triangles)))
    for k in range(triangles.shape[0]):
        a, b, c = triangles[k][0], triangles[k][1], triangles[k][2]
        cross = (x[b] - x[a]).cross(x[c] - x[a])
        twice_area = cross.norm()
        if twice_area > 0.0:
            n = cross / twice_area
            area = 0.5 * twice_area
            v_rel = wind - (v[a] + v[b] + v[c]) / 3.0
            u = v_rel.dot(n)
            vt = v_rel - u * n
            force = area * (params[8] * u * abs(u) * n + params[10] * vt.norm() * vt
                            + params[9] * abs(u) * vt)
            for q in ti.static(range(3)):
                f_out[triangles[k][q]] += force / 3.0


@ti.kernel
def eval_attraction(x: ti.template(), mass: ti.template(), G: float, softening: float,
                    f_out: ti.template()):
    """Softened inverse-square attraction, gathered per particle over all others."""
    eps2 = softening * softening
    for i in range(x.shape[0]):
        acc = ti.Vector.zero(float, 3)
        for j in range(x.shape[0]):
            if j != i:
                d = x[j] - x[i]
                r2 = d.dot(d) + eps2
                acc += mass[j] * d / (r2 * ti.sqrt(r2))
        f_out[i] += G * mass[i] * acc


def compute_forces(model, x, v, f_out, t=0.0, contacts=True, field=True):
    """Total force on every particle at positions x, velocities v and time t, into f_out;
    contacts=False leaves out the colliders' penalty forces, field=False wind and
    attraction."""
    if not model.grid_sets_forces:
        init_forces(v, model.mass, model.params, f_out)
    for k in model.spring_grids:
        eval_grid_springs(x, v, model.grid_ints, model.grid_reals, k, model.grids[k].families,
                          model.mass, model.params,
                          model.grid_sets_forces and k == model.spring_grids[0],
                          model.grid_forces, f_out)
    if model.list_spring_count:
        eval_springs(x, v, model.spring_pairs, model.spring_ks, model.spring_kd,
                     model.spring_rest, model.list_spring_count, f_out)
    if field:
        add_field_forces(model, x, v, f_out, t)
    if contacts and model.collider_count:
        collide(x, v, model.mass, model.inv_mass, model.collider_records, model.collider_ranges,
                t, f_out)


def add_field_forces(model, x, v, f_out, t):
    """f_out += wind and attraction, where the scene has them."""
    if model.wind is not None:
        if model.wind["callable"] is not None:
            model.wind_array[:3] = wind_velocity(model.wind, t)
            model.wind_params.from_numpy(model.wind_array)
        eval_wind(x, v, model.triangles, model.wind_params, t, f_out)
    if model.attraction is not None:
        eval_attraction(x, model.mass, model.attraction[0], model.attraction[1], f_out)
