"""The colliders' sweep (``guard.sweep_colliders``) for the mesh colliders baked as signed
distance fields (``geometry/sdf.py``): their paths are kept out of the exact mesh, not
only out of the field.

A particle's path is taken in the mesh's own frame, from its start x0 in the mesh's pose
at t0 to its end x1 in the pose at t0 + dt: a straight line there (a still or sliding
mesh's frame moves by a translation over the step, a turning one's turns too). Where
that line enters the exact mesh (the first face it meets from outside, through the
mesh's hierarchy: ``MeshStore.first_hit``) the path stops before the entry, where the
field's distance came down to the thickness (or to the start's, if that was nearer), and
never past the entry: the points of the line before it lie outside the mesh, so a
particle that started outside ends outside, whatever the field's interpolation error.
The stopped particle rides with the mesh to its pose at t0 + dt, its velocity into the
surface, relative to the surface's own there, removed. A particle that started inside
(by the field) and would end deeper stays where it was relative to the mesh.

A path is cast where it starts within the field's band and moved at all (the interpolated
distance is no bound there), or beyond it and is longer than the band (beyond it the
field's answer, the band, is a lower bound of the distance).
"""
import taichi as ti

from ..geometry.meshstore import pose

HALVINGS = 30     # bisection steps for a path's stop (a billionth of the way to the entry)


@ti.func
def field_paths(table, g: ti.template(), p, x0, x1, v1, t0, dt, stop_normal, back_off):
    """Particle p's path x0 -> x1 against each switched-on field row of mesh group g
    (module docstring); a stopped path ends ``back_off`` or more before the entry.
    Returns how many rows stopped it."""
    cut = 0
    for k in range(g.first, g.first + g.count):
        col = table.data[k]
        f = table.sdf.of_mesh[col.mesh]
        if col.stiffness > 0.0 and f >= 0:
            r0, c0 = pose(col, t0)
            r1, c1 = pose(col, t0 + dt)
            a = r0.transpose() @ (x0[p] - c0)
            rel = r1.transpose() @ (x1[p] - c1) - a
            length = rel.norm()
            phi0, _n0, banded = table.sdf.sample(f, a)
            stop = -1.0
            if length > 0.0 and (banded or length > phi0):
                d = rel / length
                hit = table.meshes.first_hit(col.mesh, a, d, 0.0, length, -1, -1, 0.0, True)
                if hit < length:
                    stop = _stop_before(table.sdf, f, a, d, phi0, col.thickness, hit, back_off)
            if stop < 0.0:
                phi1, _n1, _banded1 = table.sdf.sample(f, a + rel)
                if phi1 < ti.min(phi0, 0.0):
                    stop = 0.0
            if stop >= 0.0:
                _ride(table.sdf, f, col, r1, c1, a + stop * rel / ti.max(length, 1e-30), p,
                      t0 + dt, x1, v1, stop_normal)
                cut += 1
    return cut


@ti.func
def _stop_before(sdf, f, a, d, phi0, thickness, hit, back_off):
    """How far along the unit direction d from a (field distance phi0) a path that enters
    the mesh at ``hit`` stops: where the field's distance comes down to min(thickness,
    phi0) (bisection: from a start beyond it), at most ``hit`` - back_off, at least 0."""
    target = ti.max(ti.min(thickness, phi0), back_off)
    lo, hi = 0.0, hit
    if phi0 > target:
        for _ in range(HALVINGS):
            mid = 0.5 * (lo + hi)
            phi, grad, banded = sdf.sample(f, a + mid * d)
            if phi >= target:
                lo = mid
            else:
                hi = mid
    return ti.max(ti.min(lo, hit - back_off), 0.0)


@ti.func
def _ride(sdf, f, col, r1, c1, q, p, t1, x1, v1, stop_normal):
    """Particle p ends at q (the mesh's frame) carried to the pose (r1, c1) at t1, its
    velocity into the surface relative to the surface's there removed; ``stop_normal`` gets the
    surface's normal."""
    x1[p] = r1 @ q + c1
    _phi, n, u, _banded = sdf.contact(col, f, x1[p], t1)
    vn = (v1[p] - u).dot(n)
    if vn < 0.0:
        v1[p] -= vn * n
    stop_normal[p] = n
