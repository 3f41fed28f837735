"""Lecture 4's negative examples side by side: full Provot cloth, no bend springs, no shear and no bend springs."""
import tcloth

CONFIG = {
    "integrator": "symplectic_euler",
    "dt": 2.5e-4,
    "steps_per_frame": 133,
    "frames": 150,
    "camera": {"eye": (0.0, 0.9, 4.2), "target": (0.0, 0.4, 0.0), "fov": 45.0},
    "render": {"ground": -0.4},
}


def build(resolution=(24, 24), structural=(400.0, 0.05), shear=(80.0, 0.02),
          flexion=(10.0, 0.005)):
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0), air_drag=2e-4)
    nx, _ = resolution
    variants = [(-1.3, shear, flexion), (0.0, shear, None), (1.3, None, None)]
    for x, sh, fl in variants:
        scene.add_cloth(resolution=resolution, size=(1.0, 1.0), center=(x, 1.0, 0.0),
                        plane="xz", mass=0.2, structural=structural, shear=sh, flexion=fl,
                        pinned=[(0, 0), (nx - 1, 0)])
    return scene


if __name__ == "__main__":
    tcloth.cli.run_script(__file__)
