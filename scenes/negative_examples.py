"""Lecture 4's negative examples: full Provot cloth, no bend springs, no shear and no bend springs, each dropped on a sphere.

Defaults: XPBD at one step per 1/30 s frame, 3 iterations a substep, which shows the
lecture's point (without bend springs the cloth creases sharply, without shear springs
too it clings to the sphere like a skin) as symplectic Euler at 1/4000 does, at half its
cost: 0.78 wall s per simulated s on two cores where symplectic Euler took 1.4 (``python
tools/bench_scenes.py --scenes negative_examples``; ``--config
integrator=symplectic_euler --config dt=1/4000 --config steps_per_frame=133 --config
options={}`` for the other). Resting at 2 s its most stretched structural spring is 4.1
% long, symplectic Euler's 2.5 % (XPBD's default 10 iterations a substep: 8.3 %). The
folding is chaotic: after 1 s, against symplectic Euler at dt = 1e-4 s, XPBD's particles
lie about 20 mm RMS away and symplectic Euler's own at 1/4000 18 mm."""
import tcloth

CONFIG = {
    "integrator": "xpbd",
    "options": {"iterations": 3},
    "dt": 1 / 30,
    "steps_per_frame": 1,
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
