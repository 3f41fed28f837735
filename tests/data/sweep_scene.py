"""A 6 x 6 hanging cloth for the sweep tests. ``crash`` or ``interrupt`` (with ``marker``, a
path) make the first build that sees them end its process or interrupt it (SIGINT) and
leave the marker file, so that a rerun builds normally."""
import os
import signal

import tcloth


def build(k=400.0, crash=False, interrupt=False, marker=""):
    if (crash or interrupt) and not os.path.exists(marker):
        open(marker, "w").close()
        if crash:
            os._exit(3)
        os.kill(os.getpid(), signal.SIGINT)
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0))
    scene.add_cloth(resolution=(6, 6), size=(0.5, 0.5), center=(0.0, 1.0, 0.0), plane="xz",
                    mass=0.1, structural=(k, 0.05), shear=(k / 5, 0.02),
                    flexion=(k / 40, 0.005), pinned=[(0, 0), (5, 0)])
    return scene
