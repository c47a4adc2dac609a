// T-spline kernels (spec §6.3/§6.4): surface evaluation, knot derivation, dragging vectors.
// The CPU twins live in eval.rs / knots.rs / fit/ and follow the same operation order.
// Double precision throughout (PoCL supports cl_khr_fp64). Built after common.cl (grid_t,
// bucket_of, basis_poly, locate).

inline double surface_z(const grid_t g, __global const double* knots, __global const double* poly, __global const double* geom,
                        __global const double* cells, __global const uint* pstart, __global const uint* pitems,
                        __global const uint* cstart, __global const uint* citems, double s, double t) {
    int ls = 0, lt = 0;
    if (!locate(g, cells, cstart, citems, &s, &t, &ls, &lt)) return NAN;
    uint k = g.k;
    uint b = bucket_of(g, s, t);
    double z = 0.0, den = 0.0;
    for (uint q = pstart[b]; q < pstart[b + 1]; q++) {
        uint pi = pitems[q];
        double wn = weighted_basis(knots, poly, geom, k, pi, s, t, ls, lt);
        if (wn == 0.0) continue;
        __global const double* gm = geom + 4 * (size_t)pi;
        z += wn * gm[2];
        den += wn;
    }
    if (den == 0.0) return NAN;
    return z / den;
}

// ---- Element path (extraction.rs, spec §3.2 eq. 2.7): per element the numerator sum(w z N)
// and the denominator sum(w N) are one (K+1)x(K+1) block each in local (u, v); the record is
// s0 t0 s1 t1 1/(s1-s0) 1/(t1-t0) den_threshold 0, then the z*w block and the w block
// (coefficient of u^i v^j at j (K+1) + i). Same operation order as Extraction::z.

#define EGRID_ARGS const double es0, const double et0, const double eds, const double edt, const uint ens, const uint ent, const uint estride
#define MAKE_EGRID grid_t eg; eg.s0 = es0; eg.t0 = et0; eg.ds = eds; eg.dt = edt; eg.ns = ens; eg.nt = ent; eg.k = gk; eg.pad = 0

// Horner in u per row, then in v (bipoly in extraction.rs).
inline double bipoly(__global const double* c, uint n, double u, double v) {
    double acc = 0.0;
    for (int j = (int)n - 1; j >= 0; j--) {
        __global const double* row = c + (uint)j * n;
        double r = row[n - 1];
        for (int i = (int)n - 2; i >= 0; i--) r = r * u + row[i];
        acc = (j == (int)n - 1) ? r : acc * v + r;
    }
    return acc;
}

// bipoly for n = 4, unrolled (PoCL does not unroll the runtime-bound loops); same order.
inline double bipoly4(__global const double* c, double u, double v) {
    double r3 = ((c[15] * u + c[14]) * u + c[13]) * u + c[12];
    double r2 = ((c[11] * u + c[10]) * u + c[9]) * u + c[8];
    double r1 = ((c[7] * u + c[6]) * u + c[5]) * u + c[4];
    double r0 = ((c[3] * u + c[2]) * u + c[1]) * u + c[0];
    return ((r3 * v + r2) * v + r1) * v + r0;
}

#define EXT_PARAMS __global const double* knots, __global const double* poly, __global const double* geom, \
    __global const double* cells, __global const uint* pstart, __global const uint* pitems, \
    __global const uint* cstart, __global const uint* citems, \
    __global const double* edata, __global const uint* eflags, __global const uint* estart, __global const uint* eitems
#define EXT_ARGS knots, poly, geom, cells, pstart, pitems, cstart, citems, eg, estride, edata, eflags, estart, eitems

// Element path with RUN consecutive points per work item and the last element as a hint
// (as Extraction::eval_z on the CPU): PoCL runs each work item as a scalar loop, so most points
// skip the bucket search. The hint never changes a result (elements are disjoint half-open).
#define RUN 64

inline double z_ext_hint(const grid_t g, __global const double* knots, __global const double* poly, __global const double* geom,
                         __global const double* cells, __global const uint* pstart, __global const uint* pitems,
                         __global const uint* cstart, __global const uint* citems,
                         const grid_t eg, const uint stride, __global const double* edata, __global const uint* eflags,
                         __global const uint* estart, __global const uint* eitems, double s, double t, uint* hint) {
    __global const double* r = edata + (size_t)stride * *hint;
    int ok = r[0] <= s && s < r[2] && r[1] <= t && t < r[3];
    if (!ok) {
        uint b = bucket_of(eg, s, t);
        for (uint q = estart[b]; q < estart[b + 1]; q++) {
            __global const double* c = edata + (size_t)stride * eitems[q];
            if (c[0] <= s && s < c[2] && c[1] <= t && t < c[3]) { r = c; *hint = eitems[q]; ok = 1; break; }
        }
    }
    if (ok) {
        uint f = eflags[*hint];
        ok = !(((f & 1u) && s == r[0]) || ((f & 2u) && t == r[1]));
    }
    if (ok) {
        double u = (s - r[0]) * r[4];
        double v = (t - r[1]) * r[5];
        double num, den;
        if (g.k == 3) { num = bipoly4(r + 8, u, v); den = bipoly4(r + 24, u, v); }
        else { num = bipoly(r + 8, 2, u, v); den = bipoly(r + 12, 2, u, v); }
        if (den >= r[6]) return num / den;
    }
    return surface_z(g, knots, poly, geom, cells, pstart, pitems, cstart, citems, s, t);
}

__kernel void eval_points_ext(GRID_ARGS, EGRID_ARGS, EXT_PARAMS, __global const double* st, __global double* out, const uint n) {
    size_t i0 = get_global_id(0) * RUN;
    if (i0 >= n) return;
    MAKE_GRID;
    MAKE_EGRID;
    uint hint = 0;
    size_t i1 = min(i0 + RUN, (size_t)n);
    for (size_t i = i0; i < i1; i++) out[i] = z_ext_hint(g, EXT_ARGS, st[2 * i], st[2 * i + 1], &hint);
}

// Runs stay inside one grid row (work item = (row, run)).
__kernel void eval_grid_ext(GRID_ARGS, EGRID_ARGS, EXT_PARAMS, const double s0, const double t0, const double ds, const double dt,
                            const uint ns, const uint nt, __global double* out) {
    size_t w = get_global_id(0);
    uint runs = (ns + RUN - 1) / RUN;
    if (w >= (size_t)runs * nt) return;
    MAKE_GRID;
    MAKE_EGRID;
    uint j = w / runs, i0 = (w % runs) * RUN;
    uint i1 = min(i0 + RUN, ns);
    double t = t0 + (double)j * dt;
    uint hint = 0;
    for (uint i = i0; i < i1; i++) out[(size_t)j * ns + i] = z_ext_hint(g, EXT_ARGS, s0 + (double)i * ds, t, &hint);
}

// Surface heights at arbitrary parameter points st[2i], st[2i+1].
__kernel void eval_points(GRID_ARGS, __global const double* knots, __global const double* poly, __global const double* geom,
                          __global const double* cells, __global const uint* pstart, __global const uint* pitems,
                          __global const uint* cstart, __global const uint* citems,
                          __global const double* st, __global double* out, const uint n) {
    size_t i = get_global_id(0);
    if (i >= n) return;
    MAKE_GRID;
    out[i] = surface_z(g, knots, poly, geom, cells, pstart, pitems, cstart, citems, st[2 * i], st[2 * i + 1]);
}

// Surface heights on a regular grid (i, j) -> (s0 + i ds, t0 + j dt), row-major in j.
__kernel void eval_grid(GRID_ARGS, __global const double* knots, __global const double* poly, __global const double* geom,
                        __global const double* cells, __global const uint* pstart, __global const uint* pitems,
                        __global const uint* cstart, __global const uint* citems,
                        const double s0, const double t0, const double ds, const double dt,
                        const uint ns, const uint nt, __global double* out) {
    size_t idx = get_global_id(0);
    if (idx >= (size_t)ns * nt) return;
    MAKE_GRID;
    uint i = idx % ns, j = idx / ns;
    out[idx] = surface_z(g, knots, poly, geom, cells, pstart, pitems, cstart, citems, s0 + (double)i * ds, t0 + (double)j * dt);
}

// Dragging vectors (spec §4.6, A11: compared at the control point's parameter pair):
// delta_i = ref(s_i, t_i) - t(s_i, t_i); NaN where either is undefined.
__kernel void drag_vectors(GRID_ARGS, __global const double* knots, __global const double* poly, __global const double* geom,
                           __global const double* cells, __global const uint* pstart, __global const uint* pitems,
                           __global const uint* cstart, __global const uint* citems,
                           __global const double* params, __global const double* refz, __global double* delta, const uint n) {
    size_t i = get_global_id(0);
    if (i >= n) return;
    MAKE_GRID;
    double z = surface_z(g, knots, poly, geom, cells, pstart, pitems, cstart, citems, params[2 * i], params[2 * i + 1]);
    delta[i] = refz[i] - z;
}

// Nearest edge value along a line beyond `cur` (dir = +1 east/north, -1 west/south), with the
// A14 coverage test. horizontal: the line is t = at and values are s; else s = at, values t.
// Returns 0 when the ray ends (border or gap).
inline int next_knot(const grid_t g, __global const double* cells, __global const uint* cstart,
                     __global const uint* citems, int horizontal, double at, double cur, int dir, double* out) {
    uint row = horizontal ? clampidx(at, g.t0, g.dt, g.nt) : clampidx(at, g.s0, g.ds, g.ns);
    uint nb = horizontal ? g.ns : g.nt;
    uint b0 = horizontal ? clampidx(cur, g.s0, g.ds, g.ns) : clampidx(cur, g.t0, g.dt, g.nt);
    double o = horizontal ? g.s0 : g.t0;
    double d = horizontal ? g.ds : g.dt;
    // coverage: a leaf touching the line that continues beyond cur in direction dir
    int covered = 0;
    {
        uint b = horizontal ? row * g.ns + b0 : b0 * g.ns + row;
        for (uint q = cstart[b]; q < cstart[b + 1]; q++) {
            __global const double* c = cells + 4 * (size_t)citems[q];
            double lo = horizontal ? c[0] : c[1], hi = horizontal ? c[2] : c[3];
            double plo = horizontal ? c[1] : c[0], phi = horizontal ? c[3] : c[2];
            if (at < plo || at > phi) continue;
            if (dir > 0 ? (lo <= cur && cur < hi) : (lo < cur && cur <= hi)) { covered = 1; break; }
        }
    }
    if (!covered) return 0;
    double best = dir > 0 ? INFINITY : -INFINITY;
    int bi = (int)b0;
    while (bi >= 0 && bi < (int)nb) {
        double bstart = o + (double)bi * d;
        double bend = o + (double)(bi + 1) * d;
        if (dir > 0 && bi != (int)b0 && bstart > best) break;
        if (dir < 0 && bi != (int)b0 && bend < best) break;
        uint b = horizontal ? row * g.ns + (uint)bi : (uint)bi * g.ns + row;
        for (uint q = cstart[b]; q < cstart[b + 1]; q++) {
            __global const double* c = cells + 4 * (size_t)citems[q];
            double lo = horizontal ? c[0] : c[1], hi = horizontal ? c[2] : c[3];
            double plo = horizontal ? c[1] : c[0], phi = horizontal ? c[3] : c[2];
            if (at < plo || at > phi) continue;
            if (dir > 0) {
                if (lo > cur && lo < best) best = lo;
                if (hi > cur && hi < best) best = hi;
            } else {
                if (hi < cur && hi > best) best = hi;
                if (lo < cur && lo > best) best = lo;
            }
        }
        bi += dir;
    }
    if (isinf(best)) return 0;
    *out = best;
    return 1;
}

// Knot derivation (spec §3.6, §6.4): one work item per control point; writes the full local
// knot vectors (10 doubles: sigma[5], tau[5]; K = 1 uses the first 3 of each).
__kernel void derive_knots(GRID_ARGS, __global const double* cells, __global const uint* cstart,
                           __global const uint* citems, __global const double* params, __global double* out, const uint n) {
    size_t i = get_global_id(0);
    if (i >= n) return;
    MAKE_GRID;
    uint k = g.k;
    uint h = (k + 1) / 2;
    double s = params[2 * i], t = params[2 * i + 1];
    __global double* o = out + 10 * i;
    for (int dim = 0; dim < 2; dim++) {
        int horizontal = dim == 0;
        double centre = horizontal ? s : t;
        double at = horizontal ? t : s;
        __global double* dst = o + 5 * dim;
        for (uint q = 0; q < 5; q++) dst[q] = 0.0;
        for (int dir = -1; dir <= 1; dir += 2) {
            double cur = centre;
            double last = centre;
            for (uint m = 0; m < h; m++) {
                double v;
                if (next_knot(g, cells, cstart, citems, horizontal, at, cur, dir, &v)) { cur = v; last = v; }
                // padding by repetition of the outermost found value (or the centre)
                if (dir > 0) dst[h + 1 + m] = last; else dst[h - 1 - m] = last;
            }
        }
        dst[h] = centre;
    }
}
