"""Strain limiting after Provot 1995 ("Deformation constraints in a mass-spring model").

After a step, every limited spring longer than (1 + max_stretch) rest length is shortened
back to that length by moving its ends, weighted by inverse mass (a pinned end stays put).
Corrections of one pass are computed for all springs in parallel and averaged per particle
(Jacobi); ``iterations`` passes. Velocities get the position change divided by dt, so the
state stays consistent with the corrected motion.
"""
import taichi as ti

from .runtime import serial


@ti.kernel
def _limit_pass(x: ti.template(), inv_mass: ti.template(), pairs: ti.template(),
                rest: ti.template(), index: ti.template(), count: ti.i32, max_stretch: float,
                dx: ti.template(), hits: ti.template()) -> ti.i32:
    """One Jacobi pass; returns how many springs were too long."""
    ti.loop_config(serialize=ti.static(serial(dx)))
    for p in range(dx.shape[0]):
        dx[p] = ti.Vector.zero(float, 3)
        hits[p] = 0
    violated = 0
    ti.loop_config(serialize=ti.static(serial(index)))
    for k in range(count):
        s = index[k]
        i, j = pairs[s][0], pairs[s][1]
        d = x[i] - x[j]
        length = d.norm()
        limit = (1.0 + max_stretch) * rest[s]
        wsum = inv_mass[i] + inv_mass[j]
        if length > limit and wsum > 0.0:
            corr = (length - limit) / (length * wsum) * d
            dx[i] -= inv_mass[i] * corr
            dx[j] += inv_mass[j] * corr
            hits[i] += 1
            hits[j] += 1
            violated += 1
    ti.loop_config(serialize=ti.static(serial(dx)))
    for p in range(dx.shape[0]):
        if hits[p] > 0:
            x[p] += dx[p] / hits[p]
    return violated


@ti.kernel
def _correct_velocities(x_before: ti.template(), x: ti.template(), inv_dt: float,
                        v: ti.template()):
    ti.loop_config(serialize=ti.static(serial(x)))
    for p in range(x.shape[0]):
        v[p] += (x[p] - x_before[p]) * inv_dt


def limit_strain(model, state, dt):
    """Apply the model's strain limit to ``state`` in place. Returns the number of springs
    still too long before the last pass."""
    lim = model.strain_limit
    model.limit_x0.copy_from(state.x)
    violated = 0
    for _ in range(lim["iterations"]):
        violated = _limit_pass(state.x, model.inv_mass, model.spring_pairs, model.spring_rest,
                               model.limit_index, model.limit_count, lim["max_stretch"],
                               model.limit_dx, model.limit_hits)
        if violated == 0:
            break
    _correct_velocities(model.limit_x0, state.x, 1.0 / dt, state.v)
    return violated
