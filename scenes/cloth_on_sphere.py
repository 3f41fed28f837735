"""A square cloth falls onto a sphere resting on the ground and drapes over it.

Defaults: symplectic Euler at dt = 1/4000 s, 133 steps a 1/30 s frame, at 0.94 of
Gershgorin's bound with the sphere's penalty stiffness counted
(``tcloth.scene.stability.gershgorin_dt``): the lecture's integrator and penalty contact,
in real time on two cores (0.70 wall s per simulated s:
``python tools/bench_scenes.py --scenes cloth_on_sphere``)."""
import tcloth

CONFIG = {
    "integrator": "symplectic_euler",
    "dt": 2.5e-4,
    "steps_per_frame": 133,
    "frames": 150,
    "camera": {"eye": (1.7, 1.5, 2.4), "target": (0.0, 0.4, 0.0), "fov": 40.0},
}


def build(resolution=(48, 48), size=(1.2, 1.2), radius=0.35, friction=0.3):
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0), air_damping=2.304)
    scene.add_cloth(resolution=resolution, size=size, center=(0.0, 1.0, 0.0), plane="xz",
                    mass=0.2, structural=(400.0, 0.05), shear=(80.0, 0.02),
                    flexion=(10.0, 0.005), pinned=[])
    scene.add_sphere(center=(0.0, radius, 0.0), radius=radius, friction=friction)
    scene.add_plane(point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0), friction=0.5)
    return scene


if __name__ == "__main__":
    tcloth.cli.run_script(__file__)
