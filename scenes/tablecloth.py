"""A round tablecloth read from an OBJ mesh drapes over a round table into folds.

The mesh, scenes/assets/round_tablecloth.obj, has rings of vertices, finer towards the rim."""
import os

import numpy as np

import tcloth

CONFIG = {
    "integrator": "symplectic_euler",
    "dt": 2e-4,
    "steps_per_frame": 167,
    "frames": 120,
    "camera": {"eye": (1.6, 1.5, 1.8), "target": (0.0, 0.55, 0.0), "fov": 40.0},
}
ASSET = os.path.join(os.path.dirname(os.path.abspath(__file__)), "assets",
                     "round_tablecloth.obj")


def disc_mesh(rings=16, radius=0.6, grading=0.8):
    """(vertices (V,3), triangles) of a horizontal disc: a centre vertex and rings of 6 k
    vertices at radius R (k / rings)^grading, each ring turned against the last and
    joined to it by triangles in angular order, counter-clockwise seen from above."""
    pts, faces = [np.zeros(3)], []
    inner, inner_angle = [0], np.zeros(1)
    for k in range(1, rings + 1):
        count = 6 * k
        angle = 0.37 * k + 2 * np.pi * np.arange(count) / count
        r = radius * (k / rings) ** grading
        ring = list(range(len(pts), len(pts) + count))
        pts += list(np.stack([r * np.cos(angle), np.zeros(count), r * np.sin(angle)], 1))
        # the inner ring's angles lifted into [angle[0], angle[0] + 2 pi), in order
        lifted = angle[0] + np.mod(inner_angle - angle[0], 2 * np.pi)
        order = np.argsort(lifted)
        inn, ia = [inner[i] for i in order], lifted[order]
        m = len(inn)
        i = j = 0
        while i < count or j < m:
            next_outer = angle[0] + 2 * np.pi * (i + 1) / count
            next_inner = ia[j + 1] if j + 1 < m else ia[0] + 2 * np.pi
            if j == m or (i < count and next_outer <= next_inner):
                faces.append((ring[i % count], ring[(i + 1) % count], inn[j % m]))
                i += 1
            else:
                faces.append((ring[i % count], inn[(j + 1) % m], inn[j % m]))
                j += 1
        inner, inner_angle = ring, angle
    x = np.array(pts)
    tri = np.array([f for f in faces if len(set(f)) == 3])
    up = np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]])[:, 1]
    tri[up < 0] = tri[up < 0][:, ::-1]
    return x, tri


def write_asset(path=ASSET):
    """Write the disc mesh as the OBJ this scene reads."""
    x, tri = disc_mesh()
    os.makedirs(os.path.dirname(path), exist_ok=True)
    tcloth.write_obj(path, x, tri)


def build(mesh=ASSET, height=0.75, drop=0.15, friction=0.4, self_collision=True):
    if not os.path.exists(mesh):
        write_asset(mesh)
    vertices, faces = tcloth.load_obj(mesh)
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0), air_drag=2e-4)
    scene.add_mesh_cloth(vertices + [0.0, height + drop, 0.0], faces, mass=0.3,
                         structural=(300.0, 0.05), flexion=(3.0, 0.002))
    scene.add_cylinder(center=(0.0, height - 0.02, 0.0), radius=0.35, half_height=0.02,
                       friction=friction)
    scene.add_cylinder(center=(0.0, 0.5 * (height - 0.04), 0.0), radius=0.04,
                       half_height=0.5 * (height - 0.04))
    scene.add_plane(point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0), friction=0.5)
    if self_collision:
        scene.set_self_collision(thickness=0.006, friction=0.2)
    return scene


if __name__ == "__main__":
    tcloth.cli.run_script(__file__)
