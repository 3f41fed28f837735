"""Write scenes/assets/table.obj: a table for scenes/table.py, made with NumPy alone.

A rectangular top (1.2 x 0.8 m, 4 cm thick, its upper face at y = 0.75 m) with a raised
rim (a lip 2 cm wide and 1.5 cm high round its edge) on four legs (5 x 5 cm), y up, in
metres, as one closed mesh of quads: every edge is in two faces, wound counter-clockwise
seen from outside, so the collider has an inside (``Scene.add_mesh_collider``).

The solid is a union of cells of a rectilinear lattice and its surface the faces between
filled and empty cells. The lattice has a support line 3 mm either side of each crease:
the renderer shades a mesh collider with its vertex normals interpolated, and without
them a face's normal would be bent across the whole face towards the crease's average;
with them only a 3 mm strip along each edge is, which looks like a slightly rounded edge.

Usage: python tools/make_table_obj.py [--out scenes/assets/table.obj]
"""
import argparse
import os

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "..", "scenes", "assets", "table.obj")

SIZE = (1.2, 0.8)       # m: the top's extent along x and z
HEIGHT = 0.75           # m: the top's upper face (where the cloth lies)
THICKNESS = 0.04        # m: the top's thickness
RIM = (0.02, 0.015)     # m: the lip's width and its height above the top
LEG = 0.05              # m: a leg's square section
LEG_INSET = 0.05        # m: from the top's edge to a leg's outer faces
SUPPORT = 0.003         # m: the support lines' distance from a crease


def axis_lines(creases, support=SUPPORT):
    """The sorted lattice coordinates: the creases and a support line either side of
    each, inside the creases' range."""
    c = np.asarray(creases, dtype=np.float64)
    lines = np.concatenate([c, c - support, c + support])
    lines = lines[(lines >= c.min() - 1e-12) & (lines <= c.max() + 1e-12)]
    return np.unique(np.round(lines, 9))


def lattice_surface(lines, filled):
    """(vertices (V, 3), quads (Q, 4)) of the boundary of the filled cells: lines, three
    sorted coordinate arrays; filled (nx-1, ny-1, nz-1) bool. Each quad separates a
    filled cell from an empty one (or the outside), wound counter-clockwise seen from the
    empty side."""
    shape = tuple(len(a) for a in lines)
    quads = []
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3
        pad = [(0, 0)] * 3
        pad[a] = (1, 1)
        f = np.pad(filled, pad)                       # empty cells beyond each end
        lo = np.take(f, range(0, f.shape[a] - 1), axis=a)
        hi = np.take(f, range(1, f.shape[a]), axis=a)
        for sign, where in ((1, lo & ~hi), (-1, hi & ~lo)):
            idx = np.argwhere(where)                  # (plane along a, cell along b, c)
            corners = []
            for db, dc in ((0, 0), (1, 0), (1, 1), (0, 1)):
                p = idx.copy()
                p[:, b] += db
                p[:, c] += dc
                corners.append(p)
            if sign < 0:                              # the outward normal is -a
                corners = corners[::-1]
            quads.append(np.stack([np.ravel_multi_index(p.T, shape) for p in corners], 1))
    quads = np.concatenate(quads)
    used, inverse = np.unique(quads, return_inverse=True)
    grid = np.stack(np.meshgrid(*lines, indexing="ij"), -1).reshape(-1, 3)
    return grid[used], inverse.reshape(-1, 4)


def table_mesh():
    """(vertices (V, 3), quads (Q, 4)) of the table (see the module)."""
    hx, hz = SIZE[0] / 2, SIZE[1] / 2
    w, lip = RIM
    bottom = HEIGHT - THICKNESS
    leg_out = (hx - LEG_INSET, hz - LEG_INSET)
    leg_in = (leg_out[0] - LEG, leg_out[1] - LEG)
    xs = axis_lines([-hx, -hx + w, -leg_out[0], -leg_in[0], leg_in[0], leg_out[0], hx - w, hx])
    zs = axis_lines([-hz, -hz + w, -leg_out[1], -leg_in[1], leg_in[1], leg_out[1], hz - w, hz])
    ys = axis_lines([0.0, bottom, HEIGHT, HEIGHT + lip])
    cx, cy, cz = (0.5 * (a[1:] + a[:-1]) for a in (xs, ys, zs))
    X, Y, Z = np.meshgrid(cx, cy, cz, indexing="ij")
    top = (Y > bottom) & (Y < HEIGHT)
    rim = (Y > HEIGHT) & (Y < HEIGHT + lip) & ((np.abs(X) > hx - w) | (np.abs(Z) > hz - w))
    legs = ((Y < bottom) & (np.abs(X) > leg_in[0]) & (np.abs(X) < leg_out[0])
            & (np.abs(Z) > leg_in[1]) & (np.abs(Z) < leg_out[1]))
    return lattice_surface((xs, ys, zs), top | rim | legs)


def write_quads(path, vertices, quads):
    """An OBJ of ``v`` lines and 1-based ``f a b c d`` lines."""
    with open(path, "w") as f:
        f.write("# table.obj: a table with a raised rim and four legs, made by tcloth's\n"
                "# tools/make_table_obj.py (NumPy); y up, metres; one closed mesh of quads\n")
        np.savetxt(f, vertices, fmt="v %.6f %.6f %.6f")
        np.savetxt(f, quads + 1, fmt="f %d %d %d %d")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=OUT)
    args = ap.parse_args(argv)
    vertices, quads = table_mesh()
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    write_quads(args.out, vertices, quads)
    print(f"wrote {os.path.normpath(args.out)}: {len(vertices)} vertices, {len(quads)} quads")


if __name__ == "__main__":
    main()
