"""One thread against Taichi's CPU thread pool: the same loop run serialised and parallel,
side by side, for a memory-bound loop (vec3 axpy) and an arithmetic-heavy one (12
spring-like neighbour terms per item, with a square root each). Sets the default of
``tcloth.init(serial_below=...)``. Prints greppable lines

    threads.<loop>.<n>.<serial_us|parallel_us|parallel_speedup>: value

(medians of --repeats launches, synchronised).

Usage: python tools/bench_threads.py [--sizes 1024,16384,131072,1048576] [--repeats 50]
"""
import argparse
import time

import numpy as np
import taichi as ti


def build(n):
    a = ti.Vector.field(3, ti.f32, shape=n)
    b = ti.Vector.field(3, ti.f32, shape=n)
    b.from_numpy(np.random.default_rng(0).random((n, 3), dtype=np.float32))

    @ti.func
    def axpy(i):
        a[i] += 0.5 * b[i]

    @ti.func
    def springs(i):
        acc = ti.Vector.zero(ti.f32, 3)
        for k in ti.static(range(12)):
            d = b[i] - b[(i + 37 * k + 1) % n]
            length = d.norm()
            acc += (length - 0.1) / ti.max(length, 1e-9) * d
        a[i] = acc

    loops = {}
    for name, body in (("axpy", axpy), ("springs", springs)):
        @ti.kernel
        def serial_loop():
            ti.loop_config(serialize=True)
            for i in range(n):
                body(i)

        @ti.kernel
        def parallel_loop():
            for i in range(n):
                body(i)

        loops[name] = (serial_loop, parallel_loop)
    return loops


def median_us(kernel, repeats):
    kernel()
    ti.sync()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        kernel()
        ti.sync()
        times.append(time.perf_counter() - t0)
    return 1e6 * float(np.median(times))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1024,16384,131072,1048576")
    ap.add_argument("--repeats", type=int, default=50)
    args = ap.parse_args(argv)
    ti.init(arch=ti.cpu, log_level=ti.WARN)
    for n in (int(s) for s in args.sizes.split(",")):
        for name, (serial_loop, parallel_loop) in build(n).items():
            serial_us = median_us(serial_loop, args.repeats)
            parallel_us = median_us(parallel_loop, args.repeats)
            key = f"threads.{name}.{n}"
            print(f"{key}.serial_us: {serial_us:.1f}")
            print(f"{key}.parallel_us: {parallel_us:.1f}")
            print(f"{key}.parallel_speedup: {serial_us / parallel_us:.2f}", flush=True)


if __name__ == "__main__":
    main()
