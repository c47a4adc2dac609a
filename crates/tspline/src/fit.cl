// Least-squares model matrix T (spec §4.5 eq. 4.29, §6.4 "least-squares model matrix", T29):
// one work item = one sample = one row of T: the non-zero rational basis values
// T_jl = w_l N_l(s_j, t_j) / Σ_m w_m N_m(s_j, t_j) and their column indices, in ELL layout
// (MAXNZ slots per row). The host accumulates the normal equations from blocks of rows, so the
// whole matrix is never stored. The CPU twin is `ocl_fit::model_rows_cpu` (PbSpline::for_each_basis):
// the same domain test (A1 border rule), the same candidate order (bucket lists), the basis from
// the same polynomial pieces in the same operation order; agreement to rounding is tested.
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

#define MAXNZ 32

inline uint fit_clampidx(double v, double o, double d, uint n) {
    double f = floor((v - o) / d);
    f = fmax(f, 0.0);
    f = fmin(f, (double)(n - 1));
    return (uint)f;
}

// One degree-K basis function on K+2 knots kn[0..K+1] from its polynomial pieces pc (per span:
// 1/width, c0..c3 in x = (u - a)/width; PbSpline::poly), as eval::basis_poly; half-open spans
// [a,b), or (a,b] if left.
inline double fit_basis(__global const double* kn, __global const double* pc, uint k, double u, int left) {
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

// knots: 10 per point (σ then τ, 5 each); poly: 40 per point; geom: 4 per point (x, y, z, w); cells: 4 per leaf
// (s_min, t_min, s_max, t_max); bucket CSR lists of points and cells. Samples on a grid:
// (s, t) = (s0 + i·ds, t0 + j·dt), i < ns, row-major in j. count[r] = non-zeros of row r
// (0: outside the domain, MAXNZ + 1: more than MAXNZ non-zeros).
__kernel void model_rows(
    __global const double* knots, __global const double* poly, __global const double* geom, __global const double* cells,
    __global const uint* pstart, __global const uint* pitems, __global const uint* cstart, __global const uint* citems,
    const double gs0, const double gt0, const double gds, const double gdt, const uint gns, const uint gnt, const uint k,
    const double s0, const double t0, const double ds, const double dt, const uint ns, const uint nrows,
    __global uint* idx, __global double* val, __global uint* count)
{
    size_t r = get_global_id(0);
    if (r >= (size_t)ns * nrows) return;
    double s = s0 + (double)(r % ns) * ds;
    double t = t0 + (double)(r / ns) * dt;
    count[r] = 0;
    // domain test (A1), as PbSpline::locate
    uint b = fit_clampidx(t, gt0, gdt, gnt) * gns + fit_clampidx(s, gs0, gds, gns);
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
    if (!found) return;
    int ls = 0, lt = 0;
    if (k == 1) {
        ls = up_s;
        lt = up_t;
    } else {
        const double EPS = 1.0 / 1073741824.0;
        if (up_s) s = s - EPS * ws; else if (lo_s) s = s + EPS * ws;
        if (up_t) t = t - EPS * wt; else if (lo_t) t = t + EPS * wt;
    }
    b = fit_clampidx(t, gt0, gdt, gnt) * gns + fit_clampidx(s, gs0, gds, gns);
    double den = 0.0;
    uint m = 0;
    __global uint* ri = idx + (size_t)r * MAXNZ;
    __global double* rv = val + (size_t)r * MAXNZ;
    for (uint q = pstart[b]; q < pstart[b + 1]; q++) {
        uint pi = pitems[q];
        __global const double* kn = knots + 10 * (size_t)pi;
        if (s < kn[0] || s > kn[k + 1] || t < kn[5] || t > kn[5 + k + 1]) continue;
        __global const double* pc = poly + 40 * (size_t)pi;
        double bs = fit_basis(kn, pc, k, s, ls);
        if (bs == 0.0) continue;
        double bt = fit_basis(kn + 5, pc + 20, k, t, lt);
        if (bt == 0.0) continue;
        double wn = geom[4 * (size_t)pi + 3] * bs * bt;
        den += wn;
        if (m == MAXNZ) {
            count[r] = MAXNZ + 1;
            return;
        }
        ri[m] = pi;
        rv[m] = wn;
        m++;
    }
    if (den == 0.0) return;
    for (uint x = 0; x < m; x++) rv[x] = rv[x] / den;
    count[r] = m;
}
