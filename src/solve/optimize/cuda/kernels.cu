// admm-split's kernels (src/solve/optimize/cuda/split.rs drives them; the CPU
// step in admm_split.rs is the reference, line for line).
//
// Layouts: planes `K x P x Q` f32 row-major (t*PQ + r*Q + c); spectra `K x P x QC`
// (QC = Q/2 + 1, cuFFT's R2C layout: t*F + r*QC + c); the entries sensor rows see
// `M x slots x N` ((i*slots + s)*N + j), `row_frames[i*slots + s]` the frame (-1: none).
// Sums go to f64 accumulators: each block reduces its threads, then one atomicAdd per
// block and value.

typedef long long i64;

#define GRID_STRIDE(i, n) for (i64 i = (i64)blockIdx.x * blockDim.x + threadIdx.x; i < (n); i += (i64)blockDim.x * gridDim.x)

__device__ __forceinline__ double warp_sum(double v) {
    for (int o = 16; o > 0; o >>= 1) v += __shfl_down_sync(0xffffffffu, v, o);
    return v;
}

// Add `a` and `b` of every thread of the block to acc[0], acc[1]. Every thread of the
// block must call it (after its grid-stride loop). Blocks are at most 1024 threads.
__device__ void block_add2(double a, double b, double* acc) {
    __shared__ double sa[32], sb[32];
    int lane = threadIdx.x & 31, wid = threadIdx.x >> 5;
    a = warp_sum(a);
    b = warp_sum(b);
    if (lane == 0) { sa[wid] = a; sb[wid] = b; }
    __syncthreads();
    if (wid == 0) {
        int nw = (blockDim.x + 31) >> 5;
        a = lane < nw ? sa[lane] : 0.0;
        b = lane < nw ? sb[lane] : 0.0;
        a = warp_sum(a);
        b = warp_sum(b);
        if (lane == 0) { atomicAdd(acc, a); atomicAdd(acc + 1, b); }
    }
    __syncthreads();
}

// Seen entry `e = (i*slots + s)*N + j`: its (row, slot) index, its sensor pixel, and its
// place on the padded planes of frame `row_frames[is]` (-1 where the slot holds none).
struct Seen {
    i64 is, px, at;
};
__device__ __forceinline__ Seen seen_entry(i64 e, const int* row_frames, int slots, int N, int P, int Q, int off_r, int off_c) {
    Seen r;
    int j = (int)(e % N);
    r.is = e / N;
    int i = (int)(r.is / slots);
    int t = row_frames[r.is];
    r.px = (i64)i * N + j;
    r.at = t < 0 ? -1 : (i64)t * P * Q + (i64)(i + off_r) * Q + off_c + j;
    return r;
}

__device__ __forceinline__ float soft(float d, float c) {
    return d > c ? d - c : (d < -c ? d + c : 0.0f);
}

// |H_f|^2 and the spatial Laplacian's symbol `wy2 |D_y,f|^2 + wx2 |D_x,f|^2`.
extern "C" __global__ void symbols(const float2* hhat, float* h2, float* lap, int P, int Q, int QC, double wy2, double wx2) {
    const double two_pi = 6.283185307179586;
    GRID_STRIDE(f, (i64)P * QC) {
        int r = (int)(f / QC), c = (int)(f % QC);
        float2 h = hhat[f];
        h2[f] = h.x * h.x + h.y * h.y;
        double ly = 2.0 - 2.0 * cos(two_pi * r / P);
        double lx = 2.0 - 2.0 * cos(two_pi * c / Q);
        lap[f] = (float)(wy2 * ly + wx2 * lx);
    }
}

// The tridiagonal sweep's inverse pivots for penalties mu, `e = mu_tv w_t^2`.
extern "C" __global__ void factor(const float* h2, const float* lap, float* inv_pivot, int K, i64 F, float mu0, float mu1, float mu2, float e) {
    GRID_STRIDE(f, F) {
        double prev = 0.0;
        for (int t = 0; t < K; t++) {
            double deg = K == 1 ? 0.0 : ((t == 0 || t + 1 == K) ? 1.0 : 2.0);
            double a = (double)mu0 * h2[f] + (double)mu1 * lap[f] + (double)mu2 + (double)e * deg;
            double m = t > 0 ? a - (double)e * (double)e * prev : a;
            float p = (float)(1.0 / m);
            inv_pivot[(i64)t * F + f] = p;
            prev = p;
        }
    }
}

// Right-hand side in space: mu3 (w - y3) + sum_a s_a D_a^T (u_a - y2_a), s_a = mu_tv w_a
// (0: axis left out). Spatial differences periodic, temporal ones without wrap.
extern "C" __global__ void rhs_space(float* out, const float* w, const float* y3,
                                     const float* u0, const float* g0, const float* u1, const float* g1,
                                     const float* u2, const float* g2, float s0, float s1, float s2,
                                     int K, int P, int Q, float mu3) {
    i64 PQ = (i64)P * Q;
    GRID_STRIDE(e, (i64)K * PQ) {
        int t = (int)(e / PQ);
        i64 o = e - (i64)t * PQ;
        int r = (int)(o / Q), c = (int)(o % Q);
        float acc = mu3 * (w[e] - y3[e]);
        if (s0 != 0.0f) {
            float before = t > 0 ? u0[e - PQ] - g0[e - PQ] : 0.0f;
            float here = t + 1 < K ? u0[e] - g0[e] : 0.0f;
            acc += s0 * (before - here);
        }
        if (s1 != 0.0f) {
            int rp = (r + P - 1) % P;
            i64 q = (i64)t * PQ + (i64)rp * Q + c;
            acc += s1 * ((u1[q] - g1[q]) - (u1[e] - g1[e]));
        }
        if (s2 != 0.0f) {
            int cp = c == 0 ? Q - 1 : c - 1;
            i64 q = (i64)t * PQ + (i64)r * Q + cp;
            acc += s2 * ((u2[q] - g2[q]) - (u2[e] - g2[e]));
        }
        out[e] = acc;
    }
}

// The data split's residual `z - y1 - H v` placed on the planes at the seen entries
// (the planes are zeroed before).
extern "C" __global__ void scatter_resid(float* plane, const float* z, const float* y1, const float* hv, const int* row_frames,
                                         int M, int slots, int N, int P, int Q, int off_r, int off_c) {
    GRID_STRIDE(e, (i64)M * slots * N) {
        Seen w = seen_entry(e, row_frames, slots, N, P, Q, off_r, off_c);
        if (w.at >= 0) plane[w.at] = z[e] - y1[e] - hv[e];
    }
}

// Per frequency: the right-hand side's spectrum `s1 + mu1 |H|^2 vhat + mu1 conj(H) s2`
// (vhat: the previous v's), then the tridiagonal solve along time into vhat.
extern "C" __global__ void combine_sweep(float2* vhat, const float2* s1, const float2* s2, const float2* hhat, const float* h2,
                                         const float* inv_pivot, int K, i64 F, float mu1, float e) {
    GRID_STRIDE(f, F) {
        float2 h = hhat[f];
        float hh = mu1 * h2[f];
        float2 prev = make_float2(0.0f, 0.0f);
        for (int t = 0; t < K; t++) {
            i64 i = (i64)t * F + f;
            float2 a = s1[i], v = vhat[i], s = s2[i];
            // conj(h) * s * mu1
            float cr = (h.x * s.x + h.y * s.y) * mu1;
            float ci = (h.x * s.y - h.y * s.x) * mu1;
            float rr = a.x + v.x * hh + cr;
            float ri = a.y + v.y * hh + ci;
            float p = inv_pivot[i];
            if (t > 0) { rr += prev.x * e; ri += prev.y * e; }
            prev = make_float2(rr * p, ri * p);
            vhat[i] = prev;
        }
        if (e != 0.0f) {
            float2 next = vhat[(i64)(K - 1) * F + f];
            for (int t = K - 2; t >= 0; t--) {
                i64 i = (i64)t * F + f;
                float ep = e * inv_pivot[i];
                float2 c = vhat[i];
                c.x += next.x * ep;
                c.y += next.y * ep;
                vhat[i] = c;
                next = c;
            }
        }
    }
}

// out = in * hhat per frequency, over K spectra.
extern "C" __global__ void mul_h(float2* out, const float2* in, const float2* hhat, int K, i64 F) {
    GRID_STRIDE(i, (i64)K * F) {
        float2 a = in[i], h = hhat[i % F];
        out[i] = make_float2(a.x * h.x - a.y * h.y, a.x * h.y + a.y * h.x);
    }
}

extern "C" __global__ void scale(float* x, i64 n, float s) {
    GRID_STRIDE(i, n) { x[i] *= s; }
}

// hv at the seen entries from the planes of H v (unnormalised inverse: times `s`).
extern "C" __global__ void gather_seen(float* hv, const float* plane, const int* row_frames, int M, int slots, int N, int P, int Q,
                                       int off_r, int off_c, float s) {
    GRID_STRIDE(e, (i64)M * slots * N) {
        Seen w = seen_entry(e, row_frames, slots, N, P, Q, off_r, off_c);
        hv[e] = w.at >= 0 ? plane[w.at] * s : 0.0f;
    }
}

// z per sensor pixel by Sherman-Morrison (one-sided at clipped pixels), y1 += H v - z;
// acc[0] += |H v - z|^2 (primal), acc[1] += |z - z_prev|^2 (dual).
extern "C" __global__ void z_update(float* z, float* y1, const float* hv, const float* row_weights, const int* row_frames,
                                    const float* b, const unsigned char* lower, const float* mask, int M, int slots, int N,
                                    float mu, double* acc) {
    double prim = 0.0, dual = 0.0;
    GRID_STRIDE(px, (i64)M * N) {
        int i = (int)(px / N), j = (int)(px % N);
        float mk = mask ? mask[px] : 1.0f;
        bool lb = lower && lower[px];
        double ar = 0.0, aa = 0.0;
        int used = 0;
        for (int s = 0; s < slots; s++) {
            if (row_frames[(i64)i * slots + s] < 0) break;
            used++;
            double a = (double)(mk * row_weights[(i64)i * slots + s]);
            i64 q = ((i64)i * slots + s) * N + j;
            ar += a * (double)(hv[q] + y1[q]);
            aa += a * a;
        }
        float gain = (lb && ar >= (double)b[px]) ? 0.0f : (float)(((double)b[px] - ar) / ((double)mu + aa));
        for (int s = 0; s < used; s++) {
            i64 q = ((i64)i * slots + s) * N + j;
            float zn = hv[q] + y1[q] + mk * row_weights[(i64)i * slots + s] * gain;
            float pr = hv[q] - zn;
            double dz = (double)(zn - z[q]);
            dual += dz * dz;
            prim += (double)pr * pr;
            z[q] = zn;
            y1[q] += pr;
        }
    }
    block_add2(prim, dual, acc);
}

// `w_a (D_a v)` at (t, r, c): periodic in space, 0 after the last frame.
__device__ __forceinline__ float diff_at(const float* v, int axis, float wa, int t, int r, int c, int K, int P, int Q) {
    i64 PQ = (i64)P * Q;
    i64 e = (i64)t * PQ + (i64)r * Q + c;
    if (axis == 0) return t + 1 < K ? wa * (v[e + PQ] - v[e]) : 0.0f;
    if (axis == 1) return wa * (v[r + 1 == P ? (i64)t * PQ + c : e + Q] - v[e]);
    return wa * (v[c + 1 == Q ? (i64)t * PQ + (i64)r * Q : e + 1] - v[e]);
}

__device__ __forceinline__ bool inside(int axis, int r, int c, int mv, int nv) {
    if (axis == 0) return r < mv && c < nv;
    if (axis == 1) return r + 1 < mv && c < nv;
    return r < mv && c + 1 < nv;
}

// u_a = w_a D_a v (the splits at the start point).
extern "C" __global__ void diff_init(float* u, const float* v, int axis, float wa, int K, int P, int Q) {
    i64 PQ = (i64)P * Q;
    GRID_STRIDE(e, (i64)K * PQ) {
        int t = (int)(e / PQ);
        i64 o = e - (i64)t * PQ;
        u[e] = diff_at(v, axis, wa, t, (int)(o / Q), (int)(o % Q), K, P, Q);
    }
}

// One TV axis: u = shrink(D v + y) inside the video grid (free outside), y += D v - u;
// acc[0] += |D v - u|^2, acc[1] += |u - u_prev|^2.
extern "C" __global__ void u_update(float* u, float* y, const float* v, int axis, float wa, float thr, int K, int P, int Q, int mv, int nv,
                                    double* acc) {
    i64 PQ = (i64)P * Q;
    double prim = 0.0, dual = 0.0;
    GRID_STRIDE(e, (i64)K * PQ) {
        int t = (int)(e / PQ);
        i64 o = e - (i64)t * PQ;
        int r = (int)(o / Q), c = (int)(o % Q);
        float d = diff_at(v, axis, wa, t, r, c, K, P, Q);
        float s = d + y[e];
        float un = inside(axis, r, c, mv, nv) ? soft(s, thr) : s;
        double du = (double)(un - u[e]);
        dual += du * du;
        double pr = (double)(d - un);
        prim += pr * pr;
        u[e] = un;
        y[e] += d - un;
    }
    block_add2(prim, dual, acc);
}

// w = clamp(v + y3) on the video grid, 0 outside; y3 += v - w; the iterate x = w on the
// grid. acc[0..2]: primal and dual residuals; acc[2..4]: |x - x_prev|^2 and |x|^2.
extern "C" __global__ void w_update(float* w, float* y3, float* x, const float* v, int nonneg, int K, int P, int Q, int mv, int nv,
                                    double* acc) {
    i64 PQ = (i64)P * Q;
    double prim = 0.0, dual = 0.0, dx = 0.0, nx = 0.0;
    GRID_STRIDE(e, (i64)K * PQ) {
        int t = (int)(e / PQ);
        i64 o = e - (i64)t * PQ;
        int r = (int)(o / Q), c = (int)(o % Q);
        float s = v[e] + y3[e];
        bool grid = r < mv && c < nv;
        // A NaN stays NaN (fmaxf would drop it) so that the objective reports it.
        float wn = grid ? ((nonneg && !isnan(s)) ? fmaxf(s, 0.0f) : s) : 0.0f;
        double dw = (double)(wn - w[e]);
        dual += dw * dw;
        double pr = (double)(v[e] - wn);
        prim += pr * pr;
        w[e] = wn;
        y3[e] += v[e] - wn;
        if (grid) {
            i64 xi = ((i64)t * mv + r) * nv + c;
            double d = (double)(wn - x[xi]);
            dx += d * d;
            nx += (double)wn * wn;
            x[xi] = wn;
        }
    }
    block_add2(prim, dual, acc);
    block_add2(dx, nx, acc + 2);
}

// Unweighted sums of |D_t x|, |D_y x|, |D_x x| over the video grid, read from the
// planes of w (zero outside the grid). acc[0..3].
extern "C" __global__ void tv_sums(const float* w, int K, int P, int Q, int mv, int nv, double* acc) {
    i64 PQ = (i64)P * Q;
    double st = 0.0, sy = 0.0, sx = 0.0;
    GRID_STRIDE(g, (i64)K * mv * nv) {
        int t = (int)(g / ((i64)mv * nv));
        i64 o = g - (i64)t * mv * nv;
        int r = (int)(o / nv), c = (int)(o % nv);
        i64 e = (i64)t * PQ + (i64)r * Q + c;
        float x = w[e];
        if (t + 1 < K) st += fabs((double)(w[e + PQ] - x));
        if (r + 1 < mv) sy += fabs((double)(w[e + Q] - x));
        if (c + 1 < nv) sx += fabs((double)(w[e + 1] - x));
    }
    block_add2(st, sy, acc);
    block_add2(sx, 0.0, acc + 2);  // acc[3] is left 0
}

// ---- FISTA (src/solve/optimize/cuda/fista.rs; the CPU step is fista.rs) ----
// The video `x` lives on its grid `K x mv x nv`; the operator places it on the padded
// planes, convolves there and reads the sensor through the shutter and the mask.

// The video on the padded planes (0 outside its grid).
extern "C" __global__ void place(float* plane, const float* x, int K, int P, int Q, int mv, int nv) {
    i64 PQ = (i64)P * Q;
    GRID_STRIDE(e, (i64)K * PQ) {
        int t = (int)(e / PQ);
        i64 o = e - (i64)t * PQ;
        int r = (int)(o / Q), c = (int)(o % Q);
        plane[e] = (r < mv && c < nv) ? x[((i64)t * mv + r) * nv + c] : 0.0f;
    }
}

// A x per sensor pixel from the planes of H x (times `s`), into ax; acc[0] += the data
// term's sum of squares (one-sided at clipped pixels).
extern "C" __global__ void forward_gather(float* ax, const float* plane, const float* row_weights, const int* row_frames, const float* b,
                                          const unsigned char* lower, const float* mask, int M, int slots, int N, int P, int Q,
                                          int off_r, int off_c, float s, double* acc) {
    i64 PQ = (i64)P * Q;
    double sum = 0.0;
    GRID_STRIDE(px, (i64)M * N) {
        int i = (int)(px / N), j = (int)(px % N);
        float a = 0.0f;
        for (int sl = 0; sl < slots; sl++) {
            int t = row_frames[(i64)i * slots + sl];
            if (t < 0) break;
            a += row_weights[(i64)i * slots + sl] * (plane[(i64)t * PQ + (i64)(i + off_r) * Q + off_c + j] * s);
        }
        if (mask) a *= mask[px];
        ax[px] = a;
        double rr = (double)(a - b[px]);
        if (!(rr > 0.0 && lower && lower[px])) sum += rr * rr;
    }
    block_add2(sum, 0.0, acc);
}

// The residual `A y - b` (0 at a clipped pixel the model exceeds) through the mask and
// the shutter onto the planes at the seen entries (the planes are zeroed before).
extern "C" __global__ void scatter_adjoint(float* plane, const float* ay, const float* b, const unsigned char* lower, const float* mask,
                                           const float* row_weights, const int* row_frames, int M, int slots, int N, int P, int Q,
                                           int off_r, int off_c) {
    GRID_STRIDE(e, (i64)M * slots * N) {
        Seen w = seen_entry(e, row_frames, slots, N, P, Q, off_r, off_c);
        if (w.at < 0) continue;
        float r = ay[w.px] - b[w.px];
        if (lower && lower[w.px] && r > 0.0f) r = 0.0f;
        float mk = mask ? mask[w.px] : 1.0f;
        plane[w.at] = mk * row_weights[w.is] * r;
    }
}

// The gradient step on the grid: out = y - step (A^T r) with A^T r read from the planes
// (times `s`).
extern "C" __global__ void descend(float* out, const float* y, const float* plane, int K, int P, int Q, int mv, int nv, float step_s) {
    i64 PQ = (i64)P * Q;
    GRID_STRIDE(g, (i64)K * mv * nv) {
        int t = (int)(g / ((i64)mv * nv));
        i64 o = g - (i64)t * mv * nv;
        int r = (int)(o / nv), c = (int)(o % nv);
        out[g] = y[g] - step_s * plane[(i64)t * PQ + (i64)r * Q + c];
    }
}

__device__ __forceinline__ float clip_half(float d, float c) {
    float h = 0.5f * d;
    h = h > c ? c : h;
    return h < -c ? -c : h;
}

// The Haar map of the TV (the CPU's FrameProx, plain metric): per element, the pair
// terms with its successor and predecessor along each active axis, averaged over the
// J terms, then non-negativity (NaN stays NaN so the objective reports it).
extern "C" __global__ void haar_prox(float* out, const float* z, int K, int mv, int nv, float ct, float cy, float cx,
                                     int act_t, int act_y, int act_x, float inv, int nonneg) {
    i64 F = (i64)mv * nv;
    GRID_STRIDE(g, (i64)K * F) {
        int t = (int)(g / F);
        i64 o = g - (i64)t * F;
        int r = (int)(o / nv), c = (int)(o % nv);
        float zc = z[g];
        float acc = 0.0f;
        if (act_x) {
            if (c + 1 < nv) acc += clip_half(z[g + 1] - zc, cx);
            if (c > 0) acc -= clip_half(zc - z[g - 1], cx);
        }
        if (act_y) {
            if (r > 0) acc -= clip_half(zc - z[g - nv], cy);
            if (r + 1 < mv) acc += clip_half(z[g + nv] - zc, cy);
        }
        if (act_t) {
            if (t > 0) acc -= clip_half(zc - z[g - F], ct);
            if (t + 1 < K) acc += clip_half(z[g + F] - zc, ct);
        }
        float v = zc + acc * inv;
        out[g] = (nonneg && !isnan(v)) ? (v > 0.0f ? v : 0.0f) : v;
    }
}

// acc[0] += |x_new - x|^2, acc[1] += |x_new|^2.
extern "C" __global__ void change(const float* x_new, const float* x, i64 n, double* acc) {
    double d2 = 0.0, n2 = 0.0;
    GRID_STRIDE(i, n) {
        double d = (double)(x_new[i] - x[i]);
        d2 += d * d;
        n2 += (double)x_new[i] * x_new[i];
    }
    block_add2(d2, n2, acc);
}

// y = x_new + beta (x_new - x).
extern "C" __global__ void momentum(float* y, const float* x_new, const float* x, i64 n, float beta) {
    GRID_STRIDE(i, n) {
        float xn = x_new[i];
        y[i] = xn + beta * (xn - x[i]);
    }
}

// a *= hhat (conj = 0) or conj(hhat) (conj = 1) per frequency, in place, over K spectra.
extern "C" __global__ void mul_h_inplace(float2* a, const float2* hhat, int K, i64 F, int conj) {
    GRID_STRIDE(i, (i64)K * F) {
        float2 v = a[i], h = hhat[i % F];
        float hy = conj ? -h.y : h.y;
        a[i] = make_float2(v.x * h.x - v.y * hy, v.x * hy + v.y * h.x);
    }
}
