"""The golden images of ``tests/test_render_golden.py``: every shipped scene at two moments,
its particles' positions there and the picture the renderer draws of them
(``tcloth.testing.golden.frames``, which says how). The test draws the same states again
and compares.

Made with the renderer the others are compared against (the ray-casting one it replaced):

    PYTHONPATH=<a checkout of that renderer> python tools/render_golden.py

(that checkout's tcloth needs this one's tcloth/testing/ copied in: the scenes' states and
the drawing options are ``tcloth.testing.golden``'s).

Usage: python tools/render_golden.py [--scenes a,b] [--out tests/data/render_golden.npz]
[--png DIR] (--png also writes each picture as DIR/<scene>_<k>.png, to look at). The
scenes named are drawn again (a new scene added); the others' pictures in --out are kept.
"""
import argparse
import os
import sys

import numpy as np

import tcloth
from tcloth.testing.golden import frames
from tcloth.testing.scripts import scene_names

HERE = os.path.dirname(os.path.abspath(__file__))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=",".join(scene_names()))
    ap.add_argument("--out", default=os.path.join(HERE, "..", "tests", "data",
                                                  "render_golden.npz"))
    ap.add_argument("--png", help="also write each picture here as a PNG")
    args = ap.parse_args(argv)
    data = {}
    if os.path.exists(args.out):        # the other scenes' pictures are kept
        with np.load(args.out) as stored:
            data = {key: stored[key] for key in stored.files}
    for name in args.scenes.split(","):
        data.update(frames(name))
        print(f"render_golden.{name}.steps: {data[name + '.steps'].tolist()}")
        sys.stdout.flush()
        if args.png:
            os.makedirs(args.png, exist_ok=True)
            for k, image in enumerate(data[name + ".images"]):
                tcloth.write_png(os.path.join(args.png, f"{name}_{k}.png"), image)
    np.savez_compressed(args.out, **data)


if __name__ == "__main__":
    main()
