"""A Provot cloth pinned at two corners falls from horizontal and swings (the demo scene).

Defaults: symplectic Euler at dt = 1/4000 s, 133 steps a 1/30 s frame: the lecture's
integrator, one force evaluation a step, at 0.56 of the step Gershgorin's bound allows
(``tcloth.scene.stability.gershgorin_dt``); real time on two cores with room to spare
(0.24 wall s per simulated s: ``python tools/bench_scenes.py --scenes hanging_cloth``)."""
import tcloth

CONFIG = {
    "integrator": "symplectic_euler",
    "dt": 2.5e-4,
    "steps_per_frame": 133,
    "frames": 150,
    "fps": 30,
    "camera": {"eye": (1.9, 1.1, 2.4), "target": (0.0, 0.45, 0.1), "fov": 42.0},
    "render": {"ground": -0.2},
}


def build(resolution=(32, 32), size=(1.0, 1.0), structural=(400.0, 0.05),
          shear=(80.0, 0.02), flexion=(10.0, 0.005)):
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0), air_damping=1.024)
    nx, _ = resolution
    scene.add_cloth(resolution=resolution, size=size, center=(0.0, 1.0, 0.0), plane="xz",
                    mass=0.2, structural=structural, shear=shear, flexion=flexion,
                    pinned=[(0, 0), (nx - 1, 0)])
    return scene


if __name__ == "__main__":
    tcloth.cli.run_script(__file__)
