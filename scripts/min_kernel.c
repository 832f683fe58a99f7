/* The minimum work of a continuous gain map with one AP, one `coherent` IRS and boxes
 * (docs/model.md §2–3): per cell, occupancy, the direct and the IRS link's blockage by slab
 * tests, their 3GPP InF-SH path gains, the closed form |h_d| + ‖w‖₁ and the scattered power,
 * one log10; a row at a time, so that what is the same along a row (a box's x and z slabs) is
 * worked out once and the per-cell loops vectorise. One thread: the floor that the service's
 * build is compared with (issue 35, item 2), as scripts/vs_python.py's NumPy version is the
 * peer written in a high-level language. The same formulas as that file.
 *
 * Usage: min_kernel OUT.f64 nx ny x_min y_min res z  apx apy apz  cx cy cz  nx ny nz
 *                   subsurfaces per_sub carrier_ghz rician_k_db  [x0 y0 z0 x1 y1 z1]...
 * Writes the nx·ny values (dB, NaN where occupied; a[i·ny + j] the cell at x_min + i·res,
 * y_min + j·res) as raw little-endian float64 to OUT, and prints the loop's seconds (best of
 * five runs) on stdout. Build: cc -O3 -march=native -mprefer-vector-width=512 -ffast-math
 * -o min_kernel min_kernel.c -lm (-ffast-math lets GCC call the vector log and exp of glibc's
 * libmvec, as the service's own vectorised ln and exp do; on Intel's AVX-512 processors GCC 12
 * keeps the per-cell loops scalar at its default 256-bit preference, for their byte loads, and
 * the wider preference is ignored where there are no 512-bit vectors). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#define GRAZE_T 1e-12
#define ON_BOUNDARY_M 1e-9
#define MAX_BOXES 1000

typedef struct { double lo[3], hi[3]; } Box;

static Box boxes[MAX_BOXES];
static int n_boxes;

/* The slab interval of p + t·d against [lo, hi]; a segment parallel to the slab is
 * unconstrained inside it and empty outside. */
static inline void slab(double p, double d, double lo, double hi, double *t0, double *t1) {
    if (d == 0.0) {
        int inside = p > lo && p < hi;
        *t0 = inside ? -INFINITY : INFINITY;
        *t1 = inside ? INFINITY : -INFINITY;
        return;
    }
    double a = (lo - p) / d, b = (hi - p) / d;
    *t0 = fmin(a, b);
    *t1 = fmax(a, b);
}

static inline int blocked(const double *s, double x, double y, double z) {
    for (int k = 0; k < n_boxes; k++) {
        const Box *b = &boxes[k];
        double x0, x1, y0, y1, z0, z1;
        slab(s[0], x - s[0], b->lo[0], b->hi[0], &x0, &x1);
        slab(s[1], y - s[1], b->lo[1], b->hi[1], &y0, &y1);
        slab(s[2], z - s[2], b->lo[2], b->hi[2], &z0, &z1);
        double low = fmax(fmax(x0, y0), fmax(z0, 0.0));
        double high = fmin(fmin(x1, y1), fmin(z1, 1.0));
        if (high - low > GRAZE_T) return 1;
    }
    return 0;
}

/* 3GPP InF-SH path gain (linear) from ln of the squared distance (clamped to at least 1 m²):
 * the path loss is affine in log10 d, so the gain is one exponential of an affine function of
 * ln d², the NLoS branch the larger loss of the two. */
static inline double path_gain(double ln_d2, int los, double f) {
    double log10_d = 0.5 * ln_d2 / M_LN10;
    double pl = 31.84 + 21.50 * log10_d + 19.0 * f;
    double nlos = 32.4 + 23.0 * log10_d + 20.0 * f;
    pl = los ? pl : fmax(pl, nlos);
    return exp(-pl * (M_LN10 / 10.0));
}

static double now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

int main(int argc, char **argv) {
    if (argc < 21 || (argc - 21) % 6 != 0) {
        fprintf(stderr, "usage: see the comment at the top of min_kernel.c\n");
        return 2;
    }
    const char *out = argv[1];
    int nx = atoi(argv[2]), ny = atoi(argv[3]);
    double x_min = atof(argv[4]), y_min = atof(argv[5]), res = atof(argv[6]), z = atof(argv[7]);
    double ap[3] = {atof(argv[8]), atof(argv[9]), atof(argv[10])};
    double c[3] = {atof(argv[11]), atof(argv[12]), atof(argv[13])};
    double n[3] = {atof(argv[14]), atof(argv[15]), atof(argv[16])};
    double subsurfaces = atof(argv[17]), per_sub = atof(argv[18]);
    double f = log10(atof(argv[19])), kappa = pow(10.0, atof(argv[20]) / 10.0);
    n_boxes = (argc - 21) / 6;
    if (n_boxes > MAX_BOXES) return 2;
    for (int k = 0; k < n_boxes; k++)
        for (int a = 0; a < 3; a++) {
            boxes[k].lo[a] = atof(argv[21 + 6 * k + a]);
            boxes[k].hi[a] = atof(argv[24 + 6 * k + a]);
        }
    double *values = malloc(sizeof(double) * nx * ny);
    double *y = malloc(sizeof(double) * ny), *row = malloc(sizeof(double) * ny);
    unsigned char *occupied = malloc(ny), *blocked_d = malloc(ny), *blocked_u = malloc(ny);
    /* A NaN the compiler cannot fold away under -ffast-math. */
    volatile double zero = 0.0;
    double not_a_number = zero / zero;
    double elements = subsurfaces * per_sub;
    double best = INFINITY;
    for (int run = 0; run < 5; run++) {
        double started = now();
        /* The AP–IRS link, once. */
        double d2c = 0.0, facing = 0.0;
        for (int a = 0; a < 3; a++) {
            d2c += (ap[a] - c[a]) * (ap[a] - c[a]);
            facing += (ap[a] - c[a]) * n[a];
        }
        int ap_los = !blocked(ap, c[0], c[1], c[2]);
        double ap_gain = path_gain(log(fmax(d2c, 1.0)), ap_los, f), ka = ap_los ? kappa : 0.0;
        double ap_amplitude = sqrt(ap_gain * ka / (ka + 1.0));
        for (int i = 0; i < nx; i++) {
            double x = x_min + i * res;
            /* Per row, each box's x and z slabs (the same for every cell of the row) leave a
             * parameter window; per cell only the y slab remains, in loops the compiler
             * vectorises. */
            for (int j = 0; j < ny; j++) {
                y[j] = y_min + j * res;
                occupied[j] = 0;
                blocked_d[j] = 0;
                blocked_u[j] = 0;
            }
            for (int k = 0; k < n_boxes; k++) {
                const Box *b = &boxes[k];
                if (x >= b->lo[0] - ON_BOUNDARY_M && x <= b->hi[0] + ON_BOUNDARY_M)
                    for (int j = 0; j < ny; j++)
                        occupied[j] |= y[j] >= b->lo[1] - ON_BOUNDARY_M && y[j] <= b->hi[1] + ON_BOUNDARY_M;
                const double *sources[2] = {ap, c};
                unsigned char *out[2] = {blocked_d, blocked_u};
                for (int s = 0; s < 2; s++) {
                    const double *p = sources[s];
                    double x0, x1, z0, z1;
                    slab(p[0], x - p[0], b->lo[0], b->hi[0], &x0, &x1);
                    slab(p[2], z - p[2], b->lo[2], b->hi[2], &z0, &z1);
                    double low = fmax(fmax(x0, z0), 0.0), high = fmin(fmin(x1, z1), 1.0);
                    if (high - low <= GRAZE_T) continue;
                    unsigned char *o = out[s];
                    for (int j = 0; j < ny; j++) {
                        double d = y[j] - p[1];
                        double a = (b->lo[1] - p[1]) / d, e = (b->hi[1] - p[1]) / d;
                        /* d = 0: inside the open slab or not, for the whole window. */
                        int inside = p[1] > b->lo[1] && p[1] < b->hi[1];
                        double t0 = d == 0.0 ? (inside ? low : high) : fmax(fmin(a, e), low);
                        double t1 = d == 0.0 ? high : fmin(fmax(a, e), high);
                        o[j] |= t1 - t0 > GRAZE_T;
                    }
                }
            }
            double served_x = (x - c[0]) * n[0] + (z - c[2]) * n[2];
            for (int j = 0; j < ny; j++) {
                double dx = x - ap[0], dy = y[j] - ap[1], dz = z - ap[2];
                double ux = x - c[0], uy = y[j] - c[1], uz = z - c[2];
                int los = !blocked_d[j], ulos = !blocked_u[j];
                double g = path_gain(log(fmax(dx * dx + dy * dy + dz * dz, 1.0)), los, f);
                double gu = path_gain(log(fmax(ux * ux + uy * uy + uz * uz, 1.0)), ulos, f);
                double kd = los ? kappa : 0.0, ku = ulos ? kappa : 0.0;
                double served = facing > 0.0 && served_x + uy * n[1] > 0.0 ? 1.0 : 0.0;
                double direct = sqrt(g * kd / (kd + 1.0));
                double l1 = served * subsurfaces * ap_amplitude * sqrt(gu * ku / (ku + 1.0)) * per_sub;
                double tau = g / (kd + 1.0) +
                             served * ap_gain * gu * (ku + ka + 1.0) * elements / ((ka + 1.0) * (ku + 1.0));
                row[j] = 10.0 * log10((direct + l1) * (direct + l1) + tau);
            }
            for (int j = 0; j < ny; j++)
                values[i * ny + j] = occupied[j] ? not_a_number : row[j];
        }
        double took = now() - started;
        if (took < best) best = took;
    }
    FILE *file = fopen(out, "wb");
    if (!file || fwrite(values, sizeof(double), (size_t)nx * ny, file) != (size_t)nx * ny) return 1;
    fclose(file);
    printf("%.6f\n", best);
    return 0;
}
