"""A rope pinned at one end swings down from horizontal like a chain pendulum.

Defaults: velocity Verlet at dt = 1/5000 s, 167 steps a 1/30 s frame: second order in
the step for the swing's period and amplitude, 0.02 wall s per simulated s on two cores
(``python tools/bench_scenes.py --scenes rope``)."""
import tcloth

CONFIG = {
    "integrator": "verlet",
    "dt": 2e-4,
    "steps_per_frame": 167,
    "frames": 150,
    "camera": {"eye": (0.0, 0.6, 3.2), "target": (0.0, 0.5, 0.0), "fov": 45.0},
    "render": {"ground": -0.3, "particle_radius": 0.02},
}


def build(segments=40, length=1.0, stiffness=2000.0, damping=0.02):
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0), air_damping=0.041)
    scene.add_rope(start=(-0.5, 1.2, 0.0), end=(-0.5 + length, 1.2, 0.0), segments=segments,
                   mass=0.1, stiffness=stiffness, damping=damping, pinned=("start",))
    return scene


if __name__ == "__main__":
    tcloth.cli.run_script(__file__)
