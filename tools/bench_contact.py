"""The contact stress set: cloth that must never pass through cloth or a collider, at one
step per frame and at the explicit integrators' own steps (issue "contact that holds at any
step size"; docs/contact.md).

Cases (``tcloth.testing.contact_cases.CASES``; each a scene builder with its time span):
  - ``thrown_3``, ``thrown_10``: two 24 x 24 cloths of 0.5 m thrown at each other at 3 and
    10 m/s relative, no gravity, thickness 6 mm; ``thrown_unequal``: 12 x 12 cloths of 0.05
    and 0.1 kg at 1 m/s each;
  - ``twist``: a 32 x 32 cloth whose two ends turn in opposite directions (its pinned rows
    are moved from Python every step) until it wrinkles onto itself;
  - ``fold``, ``pile``: scenes/fold.py and scenes/cloth_pile.py;
  - ``box_10``, ``sphere_10``: a 24 x 24 cloth falling at 10 m/s onto a box 1 cm thick and
    onto a sphere.
Each runs with backward Euler and projective at dt = 1/60 and 1/240, and with the explicit
integrators at the scene's own dt (``--integrators``, ``--dts``). Checked with NumPy alone,
at every step: edge-triangle crossings (``tcloth.testing.crossings``; zero unless the scene started
crossed), particles inside a collider or whose path went through a thin box, the thrown
cloths' order (each cloth's centre particle stays on the side of the other it started on,
by the normal of the other's nearest triangle: they may tumble together), their linear
momentum, and no blow-up.

Prints ``contact.<case>.<integrator>.<dt>.<metric>: value`` lines (crossings_max,
inside_max, closest_collider_m, through, order_kept, momentum_drift, closing_speed_end,
ms_per_step, failsafe_steps, ...).

Usage: python tools/bench_contact.py [--cases thrown_3,fold] [--integrators backward_euler]
                                     [--dts 1/60,1/240] [--seconds S] [--explicit-chunk K]
"""
import argparse
import sys

import tcloth
from benchcsv import integrator_spec
from tcloth.testing.contact_cases import CASES, EXPLICIT, run_case


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--integrators", default="backward_euler,projective," + ",".join(EXPLICIT),
                    help="NAME or NAME:OPTION=VALUE (projective:anderson=5), "
                         "comma-separated")
    ap.add_argument("--dts", default="1/60,1/240", help="implicit integrators' steps")
    ap.add_argument("--seconds", type=float, default=None, help="shorter runs than CASES'")
    ap.add_argument("--precision", default="f32")
    ap.add_argument("--explicit-chunk", type=int, default=1,
                    help="the explicit integrators' steps per check (1: every step)")
    args = ap.parse_args(argv)
    tcloth.init(arch="cpu", precision=args.precision)
    for name in args.cases.split(","):
        for spec in args.integrators.split(","):
            integrator, options, solver = integrator_spec(spec)
            dts = [None] if integrator in EXPLICIT else [eval(d, {}) for d in args.dts.split(",")]
            for dt in dts:
                chunk = args.explicit_chunk if dt is None and name != "twist" else 1
                result = run_case(name, integrator, dt, args.seconds, chunk=chunk,
                                  options=options)
                label = "own" if dt is None else f"{dt:.4g}"
                for key, value in result.items():
                    print(f"contact.{name}.{solver}.{label}.{key}: {value}")
                sys.stdout.flush()


if __name__ == "__main__":
    main()
