"""Particles on three 25-degree ramps with friction 0.1, 0.3 and 0.6: two slide, one sticks (tan 25 = 0.47).

Defaults: symplectic Euler at dt = 1/4000 s, 133 steps a 1/30 s frame: a particle's
switch between sticking and sliding happens within a step, so small steps place it
within 1/4000 s; three particles cost nothing (0.01 wall s per simulated s:
``python tools/bench_scenes.py --scenes incline``)."""
import numpy as np

import tcloth

CONFIG = {
    "integrator": "symplectic_euler",
    "dt": 2.5e-4,
    "steps_per_frame": 133,
    "frames": 90,
    "camera": {"eye": (0.6, 1.4, 3.2), "target": (0.0, 0.4, 0.0), "fov": 45.0},
    "render": {"particle_radius": 0.05},
}


def build(angle_deg=25.0, frictions=(0.1, 0.3, 0.6), thickness=0.01):
    th = np.radians(angle_deg)
    along = np.array([np.cos(th), np.sin(th), 0.0])
    normal = np.array([-np.sin(th), np.cos(th), 0.0])
    rotation = np.stack([along, normal, (0.0, 0.0, 1.0)], axis=1)
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0))
    scene.add_plane(point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0), friction=0.5)
    half = np.array([1.0, 0.03, 0.15])
    for k, mu in enumerate(frictions):
        centre = np.array([0.0, 0.55, (k - 1) * 0.45])
        scene.add_box(centre, half, rotation=rotation, friction=mu, thickness=thickness,
                      stiffness=2000.0)
        scene.add_particles([centre + 0.6 * along + (half[1] + thickness) * normal], mass=0.05)
    return scene


if __name__ == "__main__":
    tcloth.cli.run_script(__file__)
