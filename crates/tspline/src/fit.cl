// Least-squares model matrix T (spec §4.5 eq. 4.29, §6.4 "least-squares model matrix", T29):
// one work item = one sample = one row of T: the non-zero rational basis values
// T_jl = w_l N_l(s_j, t_j) / Σ_m w_m N_m(s_j, t_j) and their column indices, in ELL layout
// (MAXNZ slots per row). The host accumulates the normal equations from blocks of rows, so the
// whole matrix is never stored. The CPU twin is `ocl_fit::model_rows_cpu` (PbSpline::for_each_basis):
// the same domain test (A1 border rule), the same candidate order (bucket lists), the basis from
// the same polynomial pieces in the same operation order (common.cl, shared with tspline.cl);
// agreement to rounding is tested. Built after common.cl.
#define MAXNZ 32

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
    grid_t g;
    g.s0 = gs0; g.t0 = gt0; g.ds = gds; g.dt = gdt; g.ns = gns; g.nt = gnt; g.k = k; g.pad = 0;
    int ls = 0, lt = 0;
    if (!locate(g, cells, cstart, citems, &s, &t, &ls, &lt)) return;
    uint b = bucket_of(g, s, t);
    double den = 0.0;
    uint m = 0;
    __global uint* ri = idx + (size_t)r * MAXNZ;
    __global double* rv = val + (size_t)r * MAXNZ;
    for (uint q = pstart[b]; q < pstart[b + 1]; q++) {
        uint pi = pitems[q];
        double wn = weighted_basis(knots, poly, geom, k, pi, s, t, ls, lt);
        if (wn == 0.0) continue;
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
