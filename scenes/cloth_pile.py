"""Three cloths dropped onto a box and each other: self-collision keeps the layers apart.

Each cloth is turned and tilted against the one below; the pile folds without crossing.

Defaults: symplectic Euler at dt = 1/4000 s, 133 steps a 1/30 s frame, at 0.72 of
Gershgorin's bound (``tcloth.scene.stability.gershgorin_dt``), for the reason the fold
gives (scenes/fold.py: on cloth lying on cloth the frame-rate solvers cost 5 to 14 times
as much). Not yet real time: 20 wall s per simulated s on two cores, 79 % of it the
contact stage (docs/benchmarks.md, "Every shipped scene against real time")."""
import numpy as np

import tcloth

CONFIG = {
    "integrator": "symplectic_euler",
    "dt": 2.5e-4,
    "steps_per_frame": 133,
    "frames": 120,
    "camera": {"eye": (1.5, 1.3, 1.9), "target": (0.0, 0.1, 0.0), "fov": 40.0},
    # one (front, back) pair per layer, bottom to top
    "render": {"cloth_colours": [[(0.85, 0.45, 0.35), (0.6, 0.3, 0.25)],
                                 [(0.35, 0.6, 0.85), (0.25, 0.4, 0.6)],
                                 [(0.95, 0.8, 0.35), (0.65, 0.55, 0.25)]]},
}


def turn(yaw, tilt):
    """Rotation by ``tilt`` about x, then ``yaw`` about the vertical."""
    cy, sy, ct, st = np.cos(yaw), np.sin(yaw), np.cos(tilt), np.sin(tilt)
    return np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]]) @ np.array(
        [[1.0, 0.0, 0.0], [0.0, ct, -st], [0.0, st, ct]])


def build(resolution=(32, 32), size=(0.8, 0.8), friction=0.3, thickness=0.006):
    # 1/s: the 2e-4 N s/m on each particle of a 0.15 kg cloth at 32 x 32, at any resolution
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0), air_damping=2e-4 * 32 * 32 / 0.15)
    for k in range(3):
        scene.add_cloth(resolution=resolution, size=size, plane="xz",
                        center=(0.08 * k, 0.15 + 0.25 * k, -0.05 * k),
                        rotation=turn(np.pi / 7 * k, 0.12 * (-1) ** k), mass=0.15,
                        structural=(400.0, 0.05), shear=(80.0, 0.02), flexion=(10.0, 0.005),
                        pinned=[])
    scene.add_box(center=(0.0, 0.06, 0.0), half_extents=(0.12, 0.06, 0.12), friction=0.5)
    scene.add_plane(point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0), friction=0.5)
    scene.set_self_collision(thickness=thickness, friction=friction)
    return scene


if __name__ == "__main__":
    tcloth.cli.run_script(__file__)
