"""A flag pinned along one edge flaps in gusty quadratic (Wejchert-Haumann) wind.

Defaults: symplectic Euler at dt = 1/4000 s, 133 steps a 1/30 s frame, at 0.78 of
Gershgorin's bound (``tcloth.scene.stability.gershgorin_dt``): the wind's quadratic,
velocity-dependent force is evaluated afresh each step, and the scene runs in real time
on two cores (0.43 wall s per simulated s: ``python tools/bench_scenes.py --scenes flag``)."""
import tcloth

CONFIG = {
    "integrator": "symplectic_euler",
    "dt": 2.5e-4,
    "steps_per_frame": 133,
    "frames": 150,
    "camera": {"eye": (1.2, 1.3, 2.6), "target": (0.55, 1.0, 0.0), "fov": 40.0},
    "render": {"ground": 0.0},
}


def build(resolution=(40, 26), size=(1.2, 0.8), wind=6.0, gust=3.0):
    # 1/s: the 1e-4 N s/m on each particle of a 0.15 kg flag at 40 x 26, at any resolution
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0), air_damping=1e-4 * 40 * 26 / 0.15)
    nx, ny = resolution
    scene.add_cloth(resolution=resolution, size=size, center=(0.6, 1.1, 0.0), plane="xy",
                    mass=0.15, structural=(600.0, 0.05), shear=(100.0, 0.02),
                    flexion=(5.0, 0.002), pinned=[(0, j) for j in range(ny)])
    scene.set_wind(velocity=(wind, 0.0, 0.6), drag=0.6, lift=0.2, tangential=0.02,
                   gust={"amplitude": (gust, 0.0, 2.0), "frequency": 0.7, "phase": 0.0})
    return scene


if __name__ == "__main__":
    tcloth.cli.run_script(__file__)
