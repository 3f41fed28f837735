"""Cusick's drape test (BS 5058, ISO 9073-9) for the fabric presets: drape coefficient and
fold count of a 30 cm disc clamped on an 18 cm support (``scenes/drape.py``).

The drape coefficient is (A_shadow - A_support) / (A_disc - A_support), A_shadow the area
of the hanging specimen's vertical projection: 1 for a stiff sheet that stays flat, near 0
for one that hangs straight down. The shadow is the union of the projected triangles,
rasterised at 0.5 mm; the folds are the maxima of the shadow's outer radius around the
support (smoothed over 10 degrees, each at least 5 mm above the minima beside it).

The specimen hangs under backward Euler at dt = 1/60 s until no particle moves faster than
0.2 mm/s at two checks 0.25 s apart (or for 8 s), from a flat start given a small random
sag (1 mm) so that its folds are not set by the mesh's symmetry. No self-contact: the
folds of these fabrics do not reach each other. The disc's triangles carry the fabric's
stretch (warp along x) and shear as a membrane (``tcloth/terms/membrane.py``); its hinges
the mean of the warp and weft bending.

    python tools/drape.py --measured            # every preset, three resolutions
    python tools/drape.py --fabrics denim --rings 24 32 --images docs/img
"""
import argparse
import importlib.util
import time
from pathlib import Path

import numpy as np

import tcloth
from tcloth.scene.fabric import PRESETS

SCENE = Path(__file__).resolve().parents[1] / "scenes" / "drape.py"

# Fabrics with a measured drape coefficient: Matsudaira, Masuda, Wada & Yokura 2015, "Shape
# factor of flared skirts compared with that of circular fabrics", J. Textile Eng. 61(6)
# 69-73, Tables 1-2 (KES bending B and weight W; Cusick drape coefficient), as transcribed
# in the GitHub repository antonbj3/3fold-motion-engine; the paper gives no tensile or
# shear numbers there, so stretch 1000 N/m and shear 10 N/m are assumed (docs/fabric.md).
# name: (density kg/m^2, B N m, measured drape coefficient)
MEASURED = {"cotton broad": (0.1238, 0.118 * 9.80665e-5, 0.829),
            "wool tropical": (0.1629, 0.067 * 9.80665e-5, 0.498),
            "polyester tropical": (0.1165, 0.077 * 9.80665e-5, 0.507),
            "polyester faille": (0.1043, 0.019 * 9.80665e-5, 0.283)}
PIXEL = 5e-4                 # m, the shadow's raster
HOLD = 2e-4                  # m/s: at rest below this speed (twice, 0.25 s apart)


def drape_scene():
    """scenes/drape.py as a module."""
    spec = importlib.util.spec_from_file_location("drape_scene", SCENE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def shadow(x, triangles, pixel=PIXEL):
    """The union of triangles (T,3) projected on the horizontal (x, z) plane, rasterised
    at ``pixel``: the (P,2) centres of the covered pixels (a pixel is covered when its
    centre is in a triangle)."""
    p = x[:, [0, 2]]
    low = p.min(0) - pixel
    shape = np.ceil((p.max(0) + pixel - low) / pixel).astype(int)
    covered = np.zeros(shape[::-1], dtype=bool)
    for a, b, c in p[triangles]:
        lo = np.floor((np.minimum(np.minimum(a, b), c) - low) / pixel).astype(int)
        hi = np.ceil((np.maximum(np.maximum(a, b), c) - low) / pixel).astype(int)
        gx, gy = np.meshgrid(low[0] + (np.arange(lo[0], hi[0]) + 0.5) * pixel,
                             low[1] + (np.arange(lo[1], hi[1]) + 0.5) * pixel)
        side = [(v[0] - u[0]) * (gy - u[1]) - (v[1] - u[1]) * (gx - u[0])
                for u, v in ((a, b), (b, c), (c, a))]
        covered[lo[1]:hi[1], lo[0]:hi[0]] |= (
            ((side[0] >= 0) & (side[1] >= 0) & (side[2] >= 0))
            | ((side[0] <= 0) & (side[1] <= 0) & (side[2] <= 0)))
    rows, cols = np.nonzero(covered)
    return low + (np.stack([cols, rows], 1) + 0.5) * pixel


def _base(r, k, step):
    """The lowest value of r from k, walking by ``step``, before one above r[k]."""
    low = r[k]
    for j in range(1, len(r)):
        v = r[(k + step * j) % len(r)]
        if v > r[k]:
            break
        low = min(low, v)
    return low


def folds(points, centre, bins=360, smooth=10, depth=5e-3):
    """The number of folds of a shadow (its covered pixels' centres, (P,2)): maxima of its
    outer radius around ``centre`` (per degree, smoothed over ``smooth`` degrees) standing
    ``depth`` above the higher of the lowest points on either side before a higher
    maximum."""
    d = points - centre
    angle = np.mod(np.degrees(np.arctan2(d[:, 1], d[:, 0])), 360.0).astype(int) % bins
    radius = np.zeros(bins)
    np.maximum.at(radius, angle, np.hypot(d[:, 0], d[:, 1]))
    wrapped = np.concatenate([radius[-smooth:], radius, radius[:smooth]])
    r = np.convolve(wrapped, np.ones(smooth) / smooth, "same")[smooth:-smooth]
    peaks = [k for k in range(bins) if r[k] >= r[k - 1] and r[k] > r[(k + 1) % bins]]
    return sum(1 for k in peaks if r[k] - max(_base(r, k, -1), _base(r, k, 1)) >= depth)


def measure(fabric, rings, max_time=8.0, seed=0, images=None):
    """(drape coefficient, folds, simulated seconds, wall seconds) of one fabric."""
    module = drape_scene()
    radius, support = 0.15, 0.09
    scene = module.build(fabric=fabric, rings=rings, radius=radius, support=support)
    sim = tcloth.Simulator(scene, integrator="backward_euler", dt=1 / 60,
                           newton_iterations=50)
    x = sim.positions()
    r = np.hypot(x[:, 0], x[:, 2])
    rng = np.random.default_rng(seed)
    x[:, 1] -= np.where(r > support, 1e-3 * rng.random(len(x)), 0.0)
    sim.set_state(positions=x)
    start = time.perf_counter()
    calm = 0
    while sim.time < max_time and calm < 2:
        sim.step(15)
        calm = calm + 1 if np.abs(sim.velocities()).max() < HOLD else 0
    wall = time.perf_counter() - start
    x = sim.positions()
    tris = scene.cloths[0].triangles
    disc_area = np.pi * radius ** 2
    support_area = np.pi * support ** 2
    covered = shadow(x, tris)
    coefficient = (len(covered) * PIXEL ** 2 - support_area) / (disc_area - support_area)
    count = folds(covered, np.zeros(2))
    if images is not None:
        views = [tcloth.render(sim, 360, 360, camera=camera) for camera in (
            {"eye": (0.38, 0.42, 0.45), "target": (0.0, 0.2, 0.0), "fov": 40.0},
            {"eye": (0.0, 0.9, 0.001), "target": (0.0, 0.2, 0.0), "fov": 30.0})]
        tcloth.write_png(Path(images) / f"drape_{fabric.name.replace(' ', '_')}_{rings}.png",
                         np.concatenate(views, axis=1))
    return coefficient, count, sim.time, wall


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fabrics", nargs="+", default=sorted(PRESETS))
    parser.add_argument("--rings", type=int, nargs="+", default=[24, 32, 48])
    parser.add_argument("--images", default=None, help="folder for a picture of each drape")
    parser.add_argument("--measured", action="store_true",
                        help="also the fabrics of MEASURED, beside their measured coefficient")
    args = parser.parse_args()
    tcloth.init(arch="cpu", precision="f32")
    runs = [(name, PRESETS[name], None) for name in args.fabrics]
    if args.measured:
        runs += [(name, tcloth.Fabric(density, 1000.0, 10.0, bending, name=name), measured)
                 for name, (density, bending, measured) in MEASURED.items()]
    print(f"{'fabric':>18} {'rings':>5} {'drape coeff.':>12} {'measured':>8} {'folds':>5} "
          f"{'sim s':>5} {'wall s':>6}")
    for name, fabric, measured in runs:
        for rings in args.rings:
            dc, count, t, wall = measure(fabric, rings, images=args.images)
            known = "" if measured is None else f"{measured:.3f}"
            print(f"{name:>18} {rings:5d} {dc:12.3f} {known:>8} {count:5d} {t:5.2f} "
                  f"{wall:6.1f}", flush=True)


if __name__ == "__main__":
    main()
