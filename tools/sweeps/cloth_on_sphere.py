"""tools/bench_accuracy.py's contact scene: a free 12 x 12 cloth of 0.6 m (k_s = 300)
falling onto a sphere with friction."""
import tcloth


def build(resolution=(12, 12)):
    scene = tcloth.Scene()
    scene.add_cloth(resolution=resolution, size=(0.6, 0.6), center=(0.0, 0.35, 0.0),
                    mass=0.2, pinned=[], structural=(300.0, 0.2), shear=(60.0, 0.1),
                    flexion=(15.0, 0.02))
    scene.add_sphere((0.0, 0.0, 0.0), 0.2, friction=0.3, thickness=0.01, stiffness=3e3)
    return scene
