"""Lecture 4's too-extensible cloth: the same heavy soft cloth hangs without (left) and with (right) Provot strain limiting at 10 %.

Defaults: symplectic Euler at dt = 1/2000 s, 67 steps a 1/30 s frame, a tenth of the
step Gershgorin's bound allows these soft springs (``tcloth.scene.stability.gershgorin_dt``):
the strain limit corrects positions after every step, and at this step the scene already
runs in real time on two cores (0.77 wall s per simulated s:
``python tools/bench_scenes.py --scenes strain_limiting``)."""
import numpy as np

import tcloth

CONFIG = {
    "integrator": "symplectic_euler",
    "dt": 5e-4,
    "steps_per_frame": 67,
    "frames": 120,
    "camera": {"eye": (0.0, 0.6, 3.6), "target": (0.0, 0.5, 0.0), "fov": 45.0},
    "render": {"ground": -0.6},
}


def build(resolution=(20, 20), stiffness=60.0):
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0), air_damping=2.0)
    nx, _ = resolution
    cloths = [scene.add_cloth(resolution=resolution, size=(1.0, 1.0), center=(x, 1.0, 0.0),
                              plane="xy", mass=2.0, structural=(stiffness, 0.2),
                              shear=(stiffness / 3, 0.05), flexion=(stiffness / 20, 0.01),
                              pinned=[(0, 0), (nx // 2, 0), (nx - 1, 0)])
              for x in (-0.7, 0.7)]
    right = cloths[1].springs
    scene.limit_strain(max_stretch=0.1, iterations=30,
                       springs=np.concatenate([right["structural"], right["shear"]]))
    return scene


if __name__ == "__main__":
    tcloth.cli.run_script(__file__)
