"""tools/bench_accuracy.py's swinging cloth: 12 x 12, 0.2 kg, 0.5 m, falling from
horizontal from two corners; structural k, shear k/5, flexion k/20, damping 0.01 sqrt(k)
(0.005 and 0.002 sqrt(k))."""
import tcloth


def build(k=300.0, resolution=(12, 12)):
    scene = tcloth.Scene()
    scene.add_cloth(resolution=resolution, size=(0.5, 0.5), plane="xz", mass=0.2,
                    structural=(k, 0.01 * k ** 0.5), shear=(k / 5, 0.005 * k ** 0.5),
                    flexion=(k / 20, 0.002 * k ** 0.5))
    return scene
