"""A three-body system under inverse-square attraction: a heavy star and two planets on near-circular orbits.

Defaults: velocity Verlet at dt = 1/1000 s, 20 steps a 1/30 s frame: symplectic and second
order, so the orbits' energy stays bounded over many periods instead of drifting as
forward Euler's does; 0.05 wall s per simulated s
(``python tools/bench_scenes.py --scenes orbit``)."""
import numpy as np

import tcloth

CONFIG = {
    "integrator": "verlet",
    "dt": 1e-3,
    "steps_per_frame": 20,
    "frames": 240,
    "camera": {"eye": (0.0, 3.0, 2.2), "target": (0.0, 0.0, 0.0), "fov": 45.0},
    "render": {"ground": -0.4, "particle_radius": 0.05},
}


def build(G=1.0, star=1.0):
    scene = tcloth.Scene(gravity=(0.0, 0.0, 0.0))
    radii, masses = np.array([0.6, 1.1]), np.array([2e-3, 1e-3])
    speeds = np.sqrt(G * star / radii)
    pos = [(0.0, 0.0, 0.0)] + [(r, 0.0, 0.0) for r in radii]
    vel = [(0.0, 0.0, 0.0)] + [(0.0, 0.0, -v) for v in speeds]
    scene.add_particles(pos, mass=[star, *masses], velocities=vel)
    scene.add_attraction(G, softening=1e-3)
    return scene


if __name__ == "__main__":
    tcloth.cli.run_script(__file__)
