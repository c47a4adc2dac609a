// Shared by both kernel families (tspline.cl: evaluation, knots, dragging; fit.cl: the model
// matrix), prepended to each source in Rust (concat! of include_str!): the bucket grid, the
// basis functions and the A1 domain test, so the two cannot drift apart. The CPU twins are
// eval.rs (BucketGrid, basis_poly, PbSpline::locate).
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

typedef struct {
    double s0, t0, ds, dt;
    uint ns, nt, k, pad;
} grid_t;

#define GRID_ARGS const double gs0, const double gt0, const double gds, const double gdt, const uint gns, const uint gnt, const uint gk
#define MAKE_GRID grid_t g; g.s0 = gs0; g.t0 = gt0; g.ds = gds; g.dt = gdt; g.ns = gns; g.nt = gnt; g.k = gk; g.pad = 0

inline uint clampidx(double v, double o, double d, uint n) {
    double f = floor((v - o) / d);
    f = fmax(f, 0.0);
    f = fmin(f, (double)(n - 1));
    return (uint)f;
}

inline uint bucket_of(const grid_t g, double s, double t) {
    return clampidx(t, g.t0, g.dt, g.nt) * g.ns + clampidx(s, g.s0, g.ds, g.ns);
}

// One degree-K basis function on K+2 knots (half-open [a,b) or (a,b] spans, A1) from its
// polynomial pieces (eval::basis_pieces): per span 1/width, c0..c3 in x = (u - a)/width.
inline double basis_poly(__global const double* kn, __global const double* pc, uint k, double u, int left) {
    if (u < kn[0] || u > kn[k + 1]) return 0.0;
    for (uint j = 0; j <= k; j++) {
        double a = kn[j], b = kn[j + 1];
        int inside = left ? (a < u && u <= b) : (a <= u && u < b);
        if (inside) {
            __global const double* c = pc + 5 * j;
            double x = (u - a) * c[0];
            return ((c[4] * x + c[3]) * x + c[2]) * x + c[1];
        }
    }
    return 0.0;
}

// w_i N_i(s, t) of point pi at a located (s, t), 0 where its blending function is zero (outside
// its support included): the one candidate test of surface_z (tspline.cl) and model_rows
// (fit.cl), as PbSpline::weighted_bases on the CPU (same tests, same operation order).
inline double weighted_basis(__global const double* knots, __global const double* poly, __global const double* geom,
                             uint k, uint pi, double s, double t, int ls, int lt) {
    __global const double* kn = knots + 10 * (size_t)pi;
    if (s < kn[0] || s > kn[k + 1] || t < kn[5] || t > kn[5 + k + 1]) return 0.0;
    __global const double* pc = poly + 40 * (size_t)pi;
    double bs = basis_poly(kn, pc, k, s, ls);
    if (bs == 0.0) return 0.0;
    double bt = basis_poly(kn + 5, pc + 20, k, t, lt);
    if (bt == 0.0) return 0.0;
    return geom[4 * (size_t)pi + 3] * bs * bt;
}

// Domain test with the A1 border rule (see PbSpline::locate): returns 0 outside; may move
// (s, t) inwards for cubic borders and sets the left-limit flags for linear upper borders.
inline int locate(const grid_t g, __global const double* cells, __global const uint* cstart,
                  __global const uint* citems, double* sp, double* tp, int* ls, int* lt) {
    double s = *sp, t = *tp;
    uint b = bucket_of(g, s, t);
    int found = 0, up_s = 1, lo_s = 1, up_t = 1, lo_t = 1;
    double ws = INFINITY, wt = INFINITY;
    for (uint q = cstart[b]; q < cstart[b + 1]; q++) {
        __global const double* c = cells + 4 * (size_t)citems[q];
        if (s < c[0] || s > c[2] || t < c[1] || t > c[3]) continue;
        found = 1;
        up_s &= (s == c[2]);
        lo_s &= (s == c[0]);
        up_t &= (t == c[3]);
        lo_t &= (t == c[1]);
        ws = fmin(ws, c[2] - c[0]);
        wt = fmin(wt, c[3] - c[1]);
    }
    if (!found) return 0;
    if (g.k == 1) { *ls = up_s; *lt = up_t; return 1; }
    const double EPS = 1.0 / 1073741824.0;
    if (up_s) s = s - EPS * ws; else if (lo_s) s = s + EPS * ws;
    if (up_t) t = t - EPS * wt; else if (lo_t) t = t + EPS * wt;
    *sp = s; *tp = t; *ls = 0; *lt = 0;
    return 1;
}

