"""A square cloth falls onto a spinning turntable and turns with it, its corners flaring out.

The turntable is a mesh collider made here with NumPy: a profile (a foot, a column and a
platter 0.8 m across) revolved about y, spinning at ``spin`` rad/s (``angular_velocity``).
Friction (0.8) carries the cloth round; its overhanging corners trail and swing out.

Defaults: XPBD at one step per 1/60 s frame with its automatic substeps: the spinning
mesh is a distance field queried inside each substep, and friction carries the cloth
round in real time on two cores (0.39 wall s per simulated s:
``python tools/bench_scenes.py --scenes turntable``)."""
import numpy as np

import tcloth

CONFIG = {
    "integrator": "xpbd",
    "options": {"substeps": "auto"},
    "dt": 1 / 60,
    "steps_per_frame": 1,
    "frames": 180,
    "camera": {"eye": (0.85, 0.95, 1.05), "target": (0.0, 0.27, 0.0), "fov": 40.0},
}
# (radius, height) of the turntable's outline, m, from the axis at the floor round to the
# axis at the platter's top; a support point 3 mm either side of each corner keeps the
# interpolated vertex normals' rounding to a 3 mm strip (smooth shading)
PROFILE = [(0.0, 0.0), (0.18, 0.0), (0.18, 0.03), (0.04, 0.03), (0.04, 0.36), (0.4, 0.36),
           (0.4, 0.39), (0.0, 0.39)]
SUPPORT = 0.003


def supported(profile, support=SUPPORT):
    """The profile with a point ``support`` either side of each inner corner."""
    p = np.asarray(profile, dtype=np.float64)
    out = [p[0]]
    for k in range(1, len(p) - 1):
        before, after = p[k - 1] - p[k], p[k + 1] - p[k]
        out += [p[k] + support * before / np.linalg.norm(before), p[k],
                p[k] + support * after / np.linalg.norm(after)]
    return np.array(out + [p[-1]])


def lathe(profile, sectors=64):
    """(vertices, triangles) of a closed solid of revolution about y: ``profile`` (r, y)
    points from the axis round to the axis (first and last at r = 0, each one vertex),
    outward-wound."""
    p = np.asarray(profile, dtype=np.float64)
    phi = 2 * np.pi * np.arange(sectors) / sectors
    ring = p[1:-1]                                    # off the axis: a ring each
    v = np.concatenate([[[0.0, p[0, 1], 0.0]],
                        np.stack([ring[:, :1] * np.cos(phi), np.repeat(ring[:, 1:], sectors, 1),
                                  ring[:, :1] * np.sin(phi)], -1).reshape(-1, 3),
                        [[0.0, p[-1, 1], 0.0]]])
    k = np.arange(sectors)
    nxt = (k + 1) % sectors
    rows = len(ring)
    tris = [np.stack([np.zeros(sectors, int), 1 + k, 1 + nxt], 1)]          # bottom cap
    for r in range(rows - 1):
        a, b = 1 + r * sectors, 1 + (r + 1) * sectors
        tris += [np.stack([a + k, b + k, a + nxt], 1), np.stack([a + nxt, b + k, b + nxt], 1)]
    top = 1 + rows * sectors
    last = 1 + (rows - 1) * sectors
    tris.append(np.stack([np.full(sectors, top), last + nxt, last + k], 1))  # top cap
    return v, np.concatenate(tris)


def build(resolution=(32, 32), size=(0.7, 0.7), drop=0.12, spin=2.0, friction=0.8):
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0), air_drag=2e-4)
    top = max(y for _, y in PROFILE)
    scene.add_cloth(resolution=resolution, size=size, center=(0.0, top + drop, 0.0),
                    plane="xz", mass=0.15, structural=(300.0, 0.05), shear=(60.0, 0.02),
                    flexion=(3.0, 0.003), pinned=[])
    scene.add_mesh_collider(lathe(supported(PROFILE)), friction=friction,
                            angular_velocity=(0.0, spin, 0.0))
    scene.add_plane(point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0), friction=0.5)
    return scene


if __name__ == "__main__":
    tcloth.cli.run_script(__file__)
