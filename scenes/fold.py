"""A cloth dropped upright onto a rod on the floor folds over onto itself (self-collision).

Its lower edge catches on the rod, it buckles and folds; the layers are kept apart.

Defaults: symplectic Euler at dt = 1/4000 s, 133 steps a 1/30 s frame, at 0.78 of
Gershgorin's bound (``tcloth.scene.stability.gershgorin_dt``). The frame-rate solvers do
not pay here: with the cloth lying on itself, projective dynamics at 1/60 (two steps a
frame) took 5.1 times, XPBD 7.9 times and VBD 14 times symplectic Euler's wall time per
simulated second, measured one after another on one machine (``python
tools/bench_scenes.py --scenes fold --config integrator=projective --config dt=1/60
--config steps_per_frame=2``, and so on). Not yet real time:
6.8 wall s per simulated s on two cores, 72 % of it the contact stage
(docs/benchmarks.md, "Every shipped scene against real time")."""
import numpy as np

import tcloth

CONFIG = {
    "integrator": "symplectic_euler",
    "dt": 2.5e-4,
    "steps_per_frame": 133,
    "frames": 120,
    "camera": {"eye": (1.7, 1.1, 1.5), "target": (0.0, 0.15, 0.0), "fov": 40.0},
}


def build(resolution=(40, 40), size=(1.0, 1.0), tilt=0.25, friction=0.3, thickness=0.006,
          air_damping=1.6):
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0), air_damping=air_damping)
    c, s = np.cos(tilt), np.sin(tilt)
    scene.add_cloth(resolution=resolution, size=size, plane="xy",
                    center=(0.0, 0.06 + 0.5 * size[1] * c, 0.5 * size[1] * s), mass=0.2,
                    rotation=[[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]],
                    structural=(400.0, 0.05), shear=(80.0, 0.02), flexion=(10.0, 0.005),
                    pinned=[])
    scene.add_box(center=(0.0, 0.02, 0.1), half_extents=(0.7, 0.02, 0.02), friction=0.8)
    scene.add_plane(point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0), friction=0.6)
    scene.set_self_collision(thickness=thickness, friction=friction)
    return scene


if __name__ == "__main__":
    tcloth.cli.run_script(__file__)
