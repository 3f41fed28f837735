"""Peirce's cantilever (ASTM D1388) in tcloth against the inextensible elastica: the table
of docs/fabric.md, each strip's tip chord angle (``tcloth.testing.cantilever``) beside the
elastica's (``tcloth.testing.elastica``).

    python tools/cantilever.py                 # the table of docs/fabric.md
    python tools/cantilever.py --alphas 2 8 16 --cells 10 20
"""
import argparse
import time

import tcloth
from tcloth.testing import elastica as reference
from tcloth.testing.cantilever import simulate


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--alphas", type=float, nargs="+", default=[1, 2, 4, 8, 16])
    parser.add_argument("--cells", type=int, nargs="+", default=[10, 20])
    parser.add_argument("--kinds", nargs="+", default=["grid", "mesh", "flexion"])
    args = parser.parse_args()
    tcloth.init(arch="cpu", precision="f64")
    print(f"{'alpha':>6} {'elastica':>9} " + " ".join(
        f"{k + ' ' + str(c):>12}" for k in args.kinds for c in args.cells))
    for alpha in args.alphas:
        row = [f"{alpha:6g}", f"{reference.chord_angle(alpha):9.2f}"]
        for kind in args.kinds:
            for cells in args.cells:
                start = time.perf_counter()
                angle, _ = simulate(kind, alpha, cells)
                row.append(f"{angle:7.2f} {time.perf_counter() - start:3.0f}s")
        print(" ".join(row), flush=True)


if __name__ == "__main__":
    main()
