"""Peirce's cantilever (ASTM D1388) in tcloth against the inextensible elastica.

A strip of fabric, clamped horizontally (its first two columns of particles pinned),
overhangs by L under its weight w per area (N/m^2). Its static tip chord angle depends only
on alpha = w L^3 / B (``tcloth.testing.elastica`` solves the elastica). The simulation runs the
strip with backward Euler at dt = 0.05 s (heavily damped: a static solve; up to 50 Newton
iterations a step, which the release from flat needs) until the angle moves by less than
1e-5 degrees in 5 steps.

The clamp line is half a cell inside the pinned region: the hinge on the last pinned column
carries the curvature of the half cell on each side of it, so the bending strip starts half
a cell before that column (the overhang L is measured from there; with L from the column
itself the angle converges at first order only).

Three strips: "grid" (``add_cloth`` with a ``Fabric``), "mesh" (``add_mesh_cloth`` on an
equilateral triangle strip, the fabric the same) and "flexion" (the lecture's Provot
cloth: structural and shear springs and flexion springs in place of the hinges, their
stiffness matching B/2 kappa^2 at the one curvature kappa = 1/L, ``flexion_for``).
"""
import numpy as np

import tcloth

DENSITY, GRAVITY, WIDTH = 0.2, 9.81, 0.02      # kg/m^2, m/s^2, m
STRETCH, SHEAR = 2000.0, 5.0                    # N/m: nearly inextensible, as the elastica


def equilateral_strip(cells, spacing, rows):
    """(vertices, triangles) of a strip of equilateral triangles along x: ``rows`` rows of
    cells + 2 vertices ``spacing`` apart, odd rows shifted by half a spacing; the strip's
    width is (rows - 1) sqrt(3)/2 spacing."""
    n = cells + 2
    j, i = np.divmod(np.arange(rows * n), n)
    vertices = np.stack([(i + 0.5 * (j % 2)) * spacing, np.zeros(len(i)),
                         j * spacing * np.sqrt(3) / 2], 1)
    tris = []
    for r in range(rows - 1):
        for c in range(n - 1):
            a, b, d, e = r * n + c, r * n + c + 1, (r + 1) * n + c, (r + 1) * n + c + 1
            tris += [(a, d, b), (b, d, e)] if r % 2 == 0 else [(a, d, e), (a, e, b)]
    return vertices, np.array(tris)


def strip(kind, alpha, cells, length=0.1):
    """(scene, clamp particle ids, tip ids, clamp offset along x (m)) of a strip whose
    overhang ``length`` bends by alpha = w L^3 / B over ``cells`` cells."""
    bending = DENSITY * GRAVITY * length ** 3 / alpha
    scene = tcloth.Scene(gravity=(0.0, -GRAVITY, 0.0))
    if kind == "mesh":
        dx = length / (cells + 0.25)
        rows = max(3, int(round(WIDTH / (dx * np.sqrt(3) / 2)))) + 1
        vertices, tris = equilateral_strip(cells, dx, rows)
        pinned = np.flatnonzero(vertices[:, 0] < 1.6 * dx)
        fabric = tcloth.Fabric(DENSITY, STRETCH, SHEAR, bending, damping=0.5)
        scene.add_mesh_cloth(vertices, [tuple(t) for t in tris.tolist()], pinned=pinned,
                             fabric=fabric)
        n = cells + 2
        first = np.arange(rows) * n
        return scene, first + 1, first + n - 1, 0.5 * dx
    dx = length / (cells + 0.5)
    nx, ny = cells + 2, max(2, int(round(WIDTH / dx)) + 1)
    pins = [(i, j) for i in (0, 1) for j in range(ny)]
    size = (dx * (nx - 1), WIDTH)
    if kind == "grid":
        fabric = tcloth.Fabric(DENSITY, STRETCH, SHEAR, bending, damping=0.5)
        cloth = scene.add_cloth(resolution=(nx, ny), size=size, center=(0, 0, 0),
                                pinned=pins, fabric=fabric)
    else:
        k_flex = flexion_for(bending, dx, size[1] / (ny - 1), 1.0 / length)
        ks, kd = STRETCH, 0.05
        cloth = scene.add_cloth(resolution=(nx, ny), size=size, center=(0, 0, 0),
                                pinned=pins, mass=DENSITY * size[0] * size[1],
                                structural=(ks, kd), shear=(SHEAR, 0.01),
                                flexion=(k_flex, 0.01))
    return scene, cloth.particles[:, 1], cloth.particles[:, -1], 0.5 * dx


def flexion_for(bending, dx, dy, curvature):
    """The flexion spring stiffness (N/m) whose energy equals B/2 kappa^2 per area at the
    one curvature kappa = ``curvature``: a node bent by theta = kappa dx shortens the
    spring over it from 2 dx by s = 2 dx (1 - cos(theta / 2)), one spring per dx dy, so
    k = B kappa^2 dx dy / s^2. At other curvatures its energy is off by (kappa/curvature)^2
    (it is quartic in the angle)."""
    s = 2.0 * dx * (1.0 - np.cos(curvature * dx / 2.0))
    return bending * curvature ** 2 * dx * dy / s ** 2


def chord_angle(sim, clamp, tip, offset):
    """The tip's chord angle (degrees below the horizontal) from the clamp line."""
    x = sim.positions()
    start = x[clamp].mean(0) - np.array([offset, 0.0, 0.0])
    end = x[tip].mean(0)
    return float(np.degrees(np.arctan2(start[1] - end[1], end[0] - start[0])))


def simulate(kind, alpha, cells, max_steps=2000):
    """(chord angle in degrees, backward Euler steps) of the strip at rest."""
    scene, clamp, tip, offset = strip(kind, alpha, cells)
    sim = tcloth.Simulator(scene, integrator="backward_euler", dt=0.05, newton_iterations=50)
    previous = None
    for steps in range(5, max_steps + 1, 5):
        sim.step(5)
        angle = chord_angle(sim, clamp, tip, offset)
        if previous is not None and abs(angle - previous) < 1e-5:
            return angle, steps
        previous = angle
    raise RuntimeError(f"the {kind} strip (alpha {alpha}, {cells} cells) did not settle "
                       f"in {max_steps} steps")
