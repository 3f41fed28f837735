"""tools/bench_stability.py's cloth: 8 x 8, 0.2 kg, 0.5 m, hanging from two corners, every
spring family at (k, kd), no drag."""
import tcloth

SIZE, MASS = 0.5, 0.2


def build(k=1000.0, kd=0.0, resolution=(8, 8)):
    scene = tcloth.Scene()
    scene.add_cloth(resolution=resolution, size=(SIZE, SIZE), plane="xy", mass=MASS,
                    structural=(k, kd), shear=(k, kd), flexion=(k, kd))
    return scene
