"""What tcloth.runtime.frontend saves: the time to build and first step a simulator (Taichi
compiling its kernels) with Taichi's position texts and sources remembered, and with
Taichi's own functions put back, side by side in fresh processes, alternating.

Prints ``frontend.<integrator>.seconds_memo`` and ``..._taichi`` (medians) and their ratio.

Usage: python tools/bench_frontend.py [--repeats 3] [--integrators backward_euler,vbd]
"""
import argparse
import statistics
import subprocess
import sys

BUILD = """
import time
import tcloth
from taichi.lang import kernel_impl
from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext
if {restore}:
    ASTTransformerContext.get_pos_info = ASTTransformerContext.get_pos_info.original
    kernel_impl.getsourcelines = kernel_impl.getsourcelines.__wrapped__
    kernel_impl.getsourcefile = kernel_impl.getsourcefile.__wrapped__
tcloth.init(arch="cpu", offline_cache=False)
scene = tcloth.Scene()
scene.add_cloth(resolution=(16, 16), size=(1.0, 1.0), center=(0.0, 1.0, 0.0))
scene.set_bending(1e-5)
scene.add_sphere((0.0, 0.5, 0.0), 0.3, friction=0.3)
start = time.perf_counter()
tcloth.Simulator(scene, integrator="{integrator}", dt=1.0 / 60.0).step(1)
print(time.perf_counter() - start)
"""


def build_seconds(integrator, restore):
    out = subprocess.run([sys.executable, "-c", BUILD.format(integrator=integrator,
                                                             restore=restore)],
                         check=True, capture_output=True, text=True).stdout
    return float(out.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--integrators", default="symplectic_euler,backward_euler,vbd")
    args = parser.parse_args()
    for integrator in args.integrators.split(","):
        memo, taichi = [], []
        for _ in range(args.repeats):
            memo.append(build_seconds(integrator, False))
            taichi.append(build_seconds(integrator, True))
        m, t = statistics.median(memo), statistics.median(taichi)
        print(f"frontend.{integrator}.seconds_memo: {m:.3f}")
        print(f"frontend.{integrator}.seconds_taichi: {t:.3f}")
        print(f"frontend.{integrator}.ratio: {t / m:.3f}", flush=True)


if __name__ == "__main__":
    main()
