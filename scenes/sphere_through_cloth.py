"""A sphere moving at constant velocity pushes through a cloth hanging from its top edge.

Defaults: symplectic Euler at dt = 1/4000 s, 133 steps a 1/30 s frame, at 0.78 of
Gershgorin's bound (``tcloth.scene.stability.gershgorin_dt``): a step moves the sphere
0.1 mm, so its contact is resolved within each step, in real time on two cores (0.51
wall s per simulated s: ``python tools/bench_scenes.py --scenes sphere_through_cloth``)."""
import tcloth

CONFIG = {
    "integrator": "symplectic_euler",
    "dt": 2.5e-4,
    "steps_per_frame": 133,
    "frames": 120,
    "camera": {"eye": (2.4, 1.3, 2.0), "target": (0.0, 0.7, 0.0), "fov": 42.0},
}


def build(resolution=(40, 40), speed=0.8, radius=0.25, friction=0.2):
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0), air_damping=1.6)
    nx, _ = resolution
    scene.add_cloth(resolution=resolution, size=(1.2, 1.2), center=(0.0, 0.8, 0.0), plane="xy",
                    mass=0.2, structural=(400.0, 0.05), shear=(80.0, 0.02),
                    flexion=(10.0, 0.005), pinned=[(i, 0) for i in range(0, nx, 3)])
    scene.add_sphere(center=(0.0, 0.65, -1.0), radius=radius, friction=friction,
                     velocity=(0.0, 0.0, speed))
    return scene


if __name__ == "__main__":
    tcloth.cli.run_script(__file__)
