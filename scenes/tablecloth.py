"""A round tablecloth read from an OBJ mesh drapes over a round table into folds.

The mesh, scenes/assets/round_tablecloth.obj, has rings of vertices, finer towards the rim.

Defaults: symplectic Euler at dt = 1/5000 s, 167 steps a 1/30 s frame, at 0.49 of
Gershgorin's bound (``tcloth.scene.stability.gershgorin_dt``), for the reason the fold
gives (scenes/fold.py). Not yet real time: 4.6 wall s per simulated s on two cores, 64 %
of it the contact stage (docs/benchmarks.md, "Every shipped scene against real time")."""
import os

import tcloth
from tcloth.geometry.primitives import disc

CONFIG = {
    "integrator": "symplectic_euler",
    "dt": 2e-4,
    "steps_per_frame": 167,
    "frames": 120,
    "camera": {"eye": (1.6, 1.5, 1.8), "target": (0.0, 0.55, 0.0), "fov": 40.0},
}
ASSET = os.path.join(os.path.dirname(os.path.abspath(__file__)), "assets",
                     "round_tablecloth.obj")


def write_asset(path=ASSET):
    """Write the disc mesh as the OBJ this scene reads."""
    x, tri = disc(rings=16, radius=0.6, grading=0.8)
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
