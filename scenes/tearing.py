"""A ball driven down through a cloth stretched on a frame punches a hole in it and tears
it open (Scene.set_tearing).

Defaults: symplectic Euler at dt = 1/4000 s, 133 steps a 1/30 s frame, at 0.63 of
Gershgorin's bound (``tcloth.scene.stability.gershgorin_dt``): springs break at the end
of a step, so a break comes within 1/4000 s of its spring reaching the threshold; real
time on two cores (0.53 wall s per simulated s:
``python tools/bench_scenes.py --scenes tearing``)."""
import tcloth

CONFIG = {
    "integrator": "symplectic_euler",
    "dt": 2.5e-4,
    "steps_per_frame": 133,
    "frames": 60,
    "camera": {"eye": (1.3, 1.5, 1.5), "target": (0.0, 0.2, 0.0), "fov": 42.0},
}


def build(resolution=(32, 32), speed=1.0, radius=0.15, max_strain=0.15):
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0), air_damping=0.5)
    nx, ny = resolution
    frame = [(i, j) for i in range(nx) for j in range(ny)
             if i in (0, nx - 1) or j in (0, ny - 1)]
    scene.add_cloth(resolution=resolution, size=(1.0, 1.0), center=(0.0, 0.5, 0.0), plane="xz",
                    mass=0.2, structural=(400.0, 0.05), shear=(80.0, 0.02),
                    flexion=(10.0, 0.005), pinned=frame)
    scene.add_sphere(center=(0.1, 0.5 + radius + 0.05, 0.05), radius=radius, friction=0.2,
                     velocity=(0.0, -speed, 0.0))
    scene.set_tearing(max_strain=max_strain)
    return scene


if __name__ == "__main__":
    tcloth.cli.run_script(__file__)
