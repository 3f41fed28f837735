"""Lecture 4's negative examples: full Provot cloth, no bend springs, no shear and no bend springs, each dropped on a sphere."""
import tcloth

CONFIG = {
    "integrator": "symplectic_euler",
    "dt": 2.5e-4,
    "steps_per_frame": 133,
    "frames": 120,
    "camera": {"eye": (0.0, 2.2, 3.6), "target": (0.0, 0.35, 0.0), "fov": 45.0},
}


def build(resolution=(32, 32), structural=(400.0, 0.05), shear=(80.0, 0.02),
          flexion=(10.0, 0.005)):
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0), air_damping=1.024)
    scene.add_plane(point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0), friction=0.5)
    variants = [(-1.3, shear, flexion), (0.0, shear, None), (1.3, None, None)]
    for x, sh, fl in variants:
        scene.add_cloth(resolution=resolution, size=(1.0, 1.0), center=(x, 0.9, 0.0),
                        plane="xz", mass=0.2, structural=structural, shear=sh, flexion=fl,
                        pinned=[])
        scene.add_sphere(center=(x, 0.3, 0.0), radius=0.3, friction=0.3)
    return scene


if __name__ == "__main__":
    tcloth.cli.run_script(__file__)
