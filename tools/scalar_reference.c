/* The substep of tools/bench_peers.py's cloth in plain C: how fast this CPU runs the same
 * arithmetic without Taichi, the reference for the roofline in docs/benchmarks.md.
 *
 * n x n particles 0.1 m apart, 0.1 kg, corners (0, 0) and (n-1, 0) fixed, structural,
 * shear and bend springs k_s = 1000, k_d = 10, gravity, symplectic Euler at 1/960 s, and a
 * finiteness check per substep. Each particle owns the six springs to (i - di, j - dj) for
 * the offsets of tcloth's grid.OWNED and scatters their forces (one thread, no atomics).
 *
 *   gcc -O3 -march=native -fno-tree-vectorize tools/scalar_reference.c -o /tmp/ref -lm
 *   /tmp/ref 128 400        # n, substeps; prints us per substep
 * (-ffast-math without -fno-tree-vectorize lets gcc vectorise what it can.)
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

typedef struct { float x, y, z; } vec3;

static double seconds(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

int main(int argc, char **argv) {
    if (argc != 3) {
        fprintf(stderr, "usage: %s n substeps\n", argv[0]);
        return 2;
    }
    const int n = atoi(argv[1]), steps = atoi(argv[2]), count = n * n;
    const float h = 0.1f, ks = 1000.0f, kd = 10.0f, mass = 0.1f, dt = 1.0f / 960.0f;
    const int owned[6][2] = {{1, 0}, {0, 1}, {1, 1}, {-1, 1}, {2, 0}, {0, 2}};
    const float rest[6] = {h, h, h * sqrtf(2.0f), h * sqrtf(2.0f), 2 * h, 2 * h};
    vec3 *x = malloc(count * sizeof(vec3)), *v = calloc(count, sizeof(vec3));
    vec3 *f = malloc(count * sizeof(vec3));
    float *inv_mass = malloc(count * sizeof(float));
    for (int j = 0; j < n; j++)
        for (int i = 0; i < n; i++) {
            x[j * n + i] = (vec3){i * h, 0.0f, j * h};
            inv_mass[j * n + i] = 1.0f / mass;
        }
    inv_mass[0] = inv_mass[n - 1] = 0.0f;

    double start = seconds();
    for (int s = 0; s < steps; s++) {
        for (int p = 0; p < count; p++)
            f[p] = (vec3){0.0f, -9.81f * mass, 0.0f};
        for (int j = 0; j < n; j++)
            for (int i = 0; i < n; i++) {
                const int p = j * n + i;
                vec3 acc = {0.0f, 0.0f, 0.0f};
                for (int k = 0; k < 6; k++) {
                    const int ii = i - owned[k][0], jj = j - owned[k][1];
                    if (ii < 0 || ii >= n || jj < 0)
                        continue;
                    const int q = jj * n + ii;
                    const float dx = x[p].x - x[q].x, dy = x[p].y - x[q].y,
                                dz = x[p].z - x[q].z;
                    const float length = sqrtf(dx * dx + dy * dy + dz * dz);
                    const float inv = 1.0f / fmaxf(length, 1e-30f);
                    const float along = (v[p].x - v[q].x) * dx + (v[p].y - v[q].y) * dy +
                                        (v[p].z - v[q].z) * dz;
                    const float c = -(ks * (length - rest[k]) + kd * inv * along) * inv;
                    acc.x += c * dx; acc.y += c * dy; acc.z += c * dz;
                    f[q].x -= c * dx; f[q].y -= c * dy; f[q].z -= c * dz;
                }
                f[p].x += acc.x; f[p].y += acc.y; f[p].z += acc.z;
            }
        for (int p = 0; p < count; p++) {
            v[p].x += dt * inv_mass[p] * f[p].x;
            v[p].y += dt * inv_mass[p] * f[p].y;
            v[p].z += dt * inv_mass[p] * f[p].z;
            x[p].x += dt * v[p].x; x[p].y += dt * v[p].y; x[p].z += dt * v[p].z;
        }
        for (int p = 0; p < count; p++)
            if (!(isfinite(x[p].x) && isfinite(x[p].y) && isfinite(x[p].z))) {
                fprintf(stderr, "particle %d not finite at substep %d\n", p, s);
                return 1;
            }
    }
    printf("n=%d us_per_substep=%.1f x[%d]=(%g, %g, %g)\n", n,
           1e6 * (seconds() - start) / steps, n + 1, x[n + 1].x, x[n + 1].y, x[n + 1].z);
    return 0;
}
