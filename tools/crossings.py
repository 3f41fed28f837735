"""Edge-triangle crossings of a saved cloth state, counted with NumPy alone
(``tcloth.testing.crossings``).

Usage: python tools/crossings.py STATE.npz (arrays "positions" and "triangles"; with
"obstacle_vertices" and "obstacle_triangles" too, as tools/newton_mesh_peer.py writes, also
the crossings with the obstacle and the points inside it, at the end and, where a
"trajectory" of every step's positions is given, the most at any step)
"""
import sys

import numpy as np

from tcloth.testing.crossings import count_crossings, count_inside, count_obstacle_crossings


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    with np.load(argv[0]) as z:
        x, tri = z["positions"], z["triangles"]
        print(f"crossings.count: {count_crossings(x, tri)}")
        if "obstacle_triangles" in z:
            mesh = z["obstacle_vertices"], z["obstacle_triangles"]
            print(f"crossings.obstacle: {count_obstacle_crossings(x, tri, *mesh)}")
            print(f"crossings.inside: {count_inside(x, *mesh)}")
            steps = z["trajectory"] if "trajectory" in z else ()
            if len(steps):
                worst = np.array([(count_obstacle_crossings(p, tri, *mesh), count_inside(p, *mesh))
                                  for p in steps.astype(np.float64)])
                print(f"crossings.obstacle_max: {worst[:, 0].max()} (steps with any: "
                      f"{(worst[:, 0] > 0).sum()} of {len(worst)})")
                print(f"crossings.inside_max: {worst[:, 1].max()} (steps with any: "
                      f"{(worst[:, 1] > 0).sum()} of {len(worst)})")


if __name__ == "__main__":
    main()
