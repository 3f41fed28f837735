"""A sleeveless dress sewn from a front and a back panel around a body of capsules, then
draped under gravity with self-collision.

The panels are one outline (``tcloth.panel``: hem, sides, armholes, shoulders, neck)
triangulated and placed flat in front of and behind the body, the back one turned half a
turn about the vertical so that both face outwards. Seams (``Scene.sew``, welded) join
the two sides and the two shoulders edge to edge; their pull closes the gaps around the
body, the welds merge each pair once it meets, and the dress hangs from the shoulders.
The body: a torso and hips (vertical capsules), a shoulder bar, arms held away from the
sides, legs and a head (a sphere), all made here.

Defaults: projective dynamics at one step per 1/60 s frame. The other frame-rate solvers
were measured on this scene one after another on one machine (``python
tools/bench_scenes.py --scenes garment --config integrator=xpbd --config dt=1/30``, and
``vbd`` at 1/60): resting, XPBD costs 0.6 of projective's wall time per simulated
second but compiles 12 kernels after the first frame (each a stall), and VBD 1.6 times
it. Not yet real
time: 13.9 wall s per simulated s on two cores (docs/benchmarks.md, "Every shipped
scene against real time")."""
import numpy as np

import tcloth

CONFIG = {
    "integrator": "projective",
    "dt": 1 / 60,
    "steps_per_frame": 1,
    "frames": 150,
    "camera": {"eye": (1.5, 1.35, 1.6), "target": (0.0, 0.95, 0.0), "fov": 40.0},
    "render": {"ground": 0.0},
}
# (u, v) corners of a panel, m: hem, right side, right armhole, right shoulder, neck (two
# edges, down to the front's scoop and up again), left shoulder, left armhole, left side
OUTLINE = ((-0.32, 0.0), (0.32, 0.0), (0.23, 0.75), (0.19, 0.92), (0.08, 0.95),
           (0.0, 0.9), (-0.08, 0.95), (-0.19, 0.92), (-0.23, 0.75))
SIDES, SHOULDERS = (1, 8), (3, 6)      # the sewn edges: right and left of each pair
HEM = 0.56                             # m: the hem's height as placed


def _turn(axis, angle):
    """The rotation by ``angle`` (rad) about a unit ``axis`` (Rodrigues)."""
    k = np.asarray(axis, dtype=np.float64)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * kx + (1.0 - np.cos(angle)) * kx @ kx


def add_body(scene, friction=0.5):
    """The body's colliders: torso, hips, shoulder bar, arms, legs and head (m)."""
    scene.add_capsule(center=(0.0, 1.22, 0.0), radius=0.12, half_height=0.12,
                      friction=friction)
    scene.add_capsule(center=(0.0, 0.98, 0.0), radius=0.13, half_height=0.04,
                      friction=friction)
    scene.add_capsule(center=(0.0, 1.40, 0.0), radius=0.06, half_height=0.12,
                      rotation=_turn((0, 0, 1), np.pi / 2), friction=friction)
    for side in (1.0, -1.0):
        tilt = _turn((0, 0, 1), side * 0.6)
        scene.add_capsule(center=np.array([side * 0.2, 1.40, 0.0]) + tilt @ (0, -0.3, 0),
                          radius=0.045, half_height=0.26, rotation=tilt, friction=friction)
        scene.add_capsule(center=(side * 0.08, 0.48, 0.0), radius=0.07, half_height=0.4,
                          friction=friction)
    scene.add_sphere(center=(0.0, 1.62, 0.0), radius=0.1, friction=friction)


def build(resolution=0.035, gap=0.16, mass=0.12, seam_stiffness=60.0, seam_damping=0.4,
          thickness=0.006):
    """The body, the two panels ``gap`` (m) in front of and behind its axis, spacing
    ``resolution`` (m), each of ``mass`` (kg), and the seams (k_s N/m, k_d N s/m)."""
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0), air_damping=0.5)
    add_body(scene)
    cut = tcloth.panel(OUTLINE, resolution)
    cloth = {"mass": mass, "structural": (300.0, 0.05), "flexion": (2.0, 0.002),
             "pinned": []}
    front = cut.add_to(scene, origin=(0.0, HEM, gap), **cloth)
    back = cut.add_to(scene, origin=(0.0, HEM, -gap), rotation=_turn((0, 1, 0), np.pi),
                      **cloth)
    for right, left in (SIDES, SHOULDERS):
        # the back is mirrored: its left edge lies on the front's right one, run backwards
        for a, b in ((right, left), (left, right)):
            scene.sew(front.edges[a], back.edges[b][::-1], stiffness=seam_stiffness,
                      damping=seam_damping, weld=True)
    scene.set_self_collision(thickness=thickness, friction=0.3)
    return scene


if __name__ == "__main__":
    tcloth.cli.run_script(__file__)
