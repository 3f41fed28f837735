"""The guard's projection against a closed form (``docs/contact.md``): two equal
flat grids one above the other, thrown at each other so that one free-flight step takes
them wholly through each other, the contact stage run once on that motion.

The closest motion to the free flight, in the mass-weighted norm, that leaves every upper
vertex ``delta`` (here the thickness) above the lower ones moves every vertex of a layer
alike: each layer by the shortfall in proportion to the other layer's mass. The inelastic
contact leaves both layers at their common velocity (total momentum over total mass) and
the kinetic energy at that of the common motion. Prints how far the guard's result is from
each (``guard_closest.<metric>: value``), with NumPy alone.

Usage: python tools/guard_closest.py [--speed 20] [--masses 0.05,0.1] [--res 8]
                                     [--precision f64]
"""
import argparse

import numpy as np

import tcloth
from tcloth.testing.contact_cases import CLOTH, guard_step

THICKNESS = 0.006
GAP = 0.1
DT = 1.0 / 60.0


def guard_once(res, masses, speed):
    """The contact stage run once on one free-flight step of two res x res grids of
    ``masses`` closing at ``speed``: (scene, the two cloths, the start x and v, the
    stage's end x1 and v1, the stage's statistics)."""
    scene = tcloth.Scene(gravity=(0.0, 0.0, 0.0))
    cloths = [scene.add_cloth(resolution=(res, res), size=(0.5, 0.5), center=(0.0, y, 0.0),
                              mass=m, **CLOTH)
              for y, m in zip((GAP / 2, -GAP / 2), masses)]
    scene.set_self_collision(thickness=THICKNESS)
    sim = tcloth.Simulator(scene, "symplectic_euler", dt=DT)
    x = scene.positions.astype(np.float64)
    v = np.zeros_like(x)
    for c, sign in zip(cloths, (-1.0, 1.0)):
        v[c.particles.ravel(), 1] = sign * speed / 2
    sim.set_state(positions=x, velocities=v)
    x1, v1 = guard_step(sim, x, v, DT)
    return scene, cloths, x, v, x1, v1, sim.contact_stats()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--speed", type=float, default=20.0, help="relative speed, m/s")
    ap.add_argument("--masses", default="0.05,0.1", help="the upper and lower grid's kg")
    ap.add_argument("--res", type=int, default=8)
    ap.add_argument("--precision", default="f64")
    args = ap.parse_args(argv)
    masses = tuple(float(m) for m in args.masses.split(","))
    if len(masses) != 2 or min(masses) <= 0.0:
        ap.error(f"--masses must be two positive masses (got {args.masses!r})")
    if args.res < 2:
        ap.error(f"--res must be at least 2 (got {args.res})")
    if args.speed * DT <= GAP + THICKNESS:
        ap.error(f"--speed must take the grids through each other in one step of {DT:.4g} s "
                 f"(above {(GAP + THICKNESS) / DT:.3g} m/s; got {args.speed})")
    tcloth.init(arch="cpu", precision=args.precision)
    scene, cloths, x, v, x1, v1, stats = guard_once(args.res, masses, args.speed)
    short = THICKNESS + args.speed * DT - GAP
    common = (masses[1] - masses[0]) * args.speed / 2 / sum(masses)
    out = {"shortfall_m": short, "common_velocity": common}
    for name, c, sign, other in (("upper", cloths[0], 1.0, masses[1]),
                                 ("lower", cloths[1], -1.0, masses[0])):
        ids = c.particles.ravel()
        move = (x1 - x - DT * v)[ids]
        closest = sign * short * other / sum(masses)
        out[f"{name}_closest_move_m"] = closest
        out[f"{name}_move_min_m"], out[f"{name}_move_max_m"] = move[:, 1].min(), move[:, 1].max()
        out[f"{name}_move_error_max"] = np.abs(move - [0.0, closest, 0.0]).max() / short
        out[f"{name}_velocity_min"] = v1[ids, 1].min()
        out[f"{name}_velocity_max"] = v1[ids, 1].max()
    m = scene.masses[:, None]
    out["kinetic_before_J"] = 0.5 * float(np.sum(m * v * v))
    out["kinetic_after_J"] = 0.5 * float(np.sum(m * v1 * v1))
    out["kinetic_inelastic_J"] = 0.5 * sum(masses) * common ** 2
    out["momentum_change"] = float(np.abs((m * (v1 - v)).sum(0)).max())
    for key in ("guard_corrections", "guard_sweeps", "failsafe_steps"):
        out[key] = stats[key]
    for key, value in out.items():
        print(f"guard_closest.{key}: {value:.6g}")


if __name__ == "__main__":
    main()
