"""The elastica's table: the tip chord angle of Peirce's cantilever against alpha = w L^3 / B
(``tcloth.testing.elastica`` solves it).

Usage: python tools/elastica.py [--alphas A [A ...]] [--csv PATH]
prints alpha, chord angle (degrees), x_tip / L and y_tip / L for alpha = 1, 2, ..., 16 or the
alphas given, and with --csv also writes them as CSV.
"""
import argparse
import csv

from tcloth.testing.elastica import table

HEADER = ("alpha", "chord_angle_deg", "x_tip_over_L", "y_tip_over_L")


def main(argv=None):
    """Command line: print the table, and write it as CSV with --csv."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--alphas", type=float, nargs="+", default=[float(a) for a in range(1, 17)],
                        help="values of alpha = w L^3 / B (default 1 2 ... 16)")
    parser.add_argument("--csv", metavar="PATH", help="also write the table as CSV to PATH")
    args = parser.parse_args(argv)
    try:
        rows = table(args.alphas)
    except ValueError as err:
        parser.error(str(err))
    print(f"{'alpha':>10} {'chord angle (deg)':>18} {'x_tip/L':>12} {'y_tip/L':>12}")
    for alpha, angle, x, y in rows:
        print(f"{alpha:10.4g} {angle:18.4f} {x:12.6f} {y:12.6f}")
    if args.csv:
        with open(args.csv, "w", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow(HEADER)
            writer.writerows([repr(v) for v in row] for row in rows)


if __name__ == "__main__":
    main()
