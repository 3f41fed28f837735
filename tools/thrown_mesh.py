"""The mesh colliders' stress set (``tcloth.testing.thrown_mesh``): a cloth thrown down at
10 m/s onto a mesh plate 1 cm thick or a mesh sphere (still, spinning or breathing), every
integrator, with the NumPy counts of crossings and particles inside after every step.

``thrown(integrator, collider, motion, dt=None, sdf=False)`` runs one case and returns what
it found; ``tests/test_mesh_collider.py`` asserts on every case at 1/60 s and the
integrators' own dt (``tests/test_mesh_fields.py`` on some with sdf="auto"). As a tool it
runs the matrix at a dt of your choosing (the issue's guarantee holds up to 1/30 s) and
prints one line a case, as the benchmarks print their figures:

    python tools/thrown_mesh.py --dt 1/30 [--integrators projective,vbd] [--colliders plate]
                                [--sdf]

    thrown.<integrator>.<collider>[.<motion>]: crossings <n> inside <n> paths <n> closest <m>
        steps <n> (<path>, <n> fallbacks, <s> s) [error]

(--sdf: the obstacles as distance fields where they can be, ``add_mesh_collider``'s
sdf="auto"; by default the certified pairs, whose guarantee the crossings count.)
"""
import argparse
import time
from fractions import Fraction

import tcloth
from tcloth.testing.thrown_mesh import INTEGRATORS, OBSTACLES, thrown


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dt", default=None,
                        help="step (s, or a fraction such as 1/30); the integrators' own "
                             "by default")
    parser.add_argument("--integrators", default=",".join(INTEGRATORS))
    parser.add_argument("--colliders", default="plate,sphere",
                        help="plate, sphere (the sphere still, spinning and breathing)")
    parser.add_argument("--arch", default="cpu")
    parser.add_argument("--sdf", action="store_true",
                        help="the obstacles as distance fields where they can be "
                             "(sdf=\"auto\"; default: the certified pairs)")
    args = parser.parse_args(argv)
    dt = float(Fraction(args.dt)) if args.dt else None
    if dt is not None and not dt > 0:
        parser.error(f"--dt must be positive (got {args.dt!r})")
    integrators = args.integrators.split(",")
    for name in integrators:
        if name not in INTEGRATORS:
            parser.error(f"--integrators: unknown integrator {name!r} "
                         f"(one of {', '.join(INTEGRATORS)})")
    colliders = args.colliders.split(",")
    tcloth.init(args.arch)
    for integrator in integrators:
        for collider, motion in OBSTACLES:
            if collider not in colliders:
                continue
            start = time.perf_counter()
            r = thrown(integrator, collider, motion, dt, "auto" if args.sdf else False)
            name = ".".join(p for p in ("thrown", integrator, collider, motion) if p)
            print(f"{name}: crossings {r['crossings']} inside {r['inside']} paths "
                  f"{r['paths']} closest {r['closest']:.4f} steps {r['steps']} ({r['path']}, "
                  f"{r['fallbacks']} fallbacks, {time.perf_counter() - start:.0f} s)"
                  + (f" error: {r['error'][:160]}" if r["error"] else ""), flush=True)


if __name__ == "__main__":
    main()
