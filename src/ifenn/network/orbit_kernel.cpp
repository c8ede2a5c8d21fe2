// One layer of the PICNN as orbit sums + a small matrix product, fused, on rows of pixels.
//
// Compiled at first use by ifenn/network/orbit_kernel.py (g++ -O3 -march=native) and called through
// ctypes. The arithmetic is that of ifenn/network/orbit.py (OrbitEvaluator): for every output pixel
// p of a run, the n_free orbit sums S_ab of every input channel in the (2R+1)^2 window
// around p, then z_o = sum_(k, i) w[o, k * c_in + i] S_k(x_i)(p) and the activation. The
// difference is that the sums of a chunk of 32 pixels never leave the L1 cache and the
// product keeps its 12 x 32 outputs in registers (GCC vector extensions: AVX-512 where the
// CPU has it, narrower vectors elsewhere).
//
// Buffers are padded images of shape (channels, ny + 2R, nx + 2R), row-major, with at least
// 32 floats of slack after the last one (the last chunk of a run reads past its end; what it
// reads there is not stored). Runs are (row, first column, end column) in image coordinates
// (0 <= row < ny, 0 <= first < end <= nx); outputs are written inside the padding only.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <memory>
#include <vector>

namespace {

typedef float v16 __attribute__((vector_size(64)));
typedef int32_t i16 __attribute__((vector_size(64)));
constexpr int PV = 2;            // vectors of 16 pixels per chunk
constexpr int CHUNK = 16 * PV;

inline v16 load(const float* p) {
    v16 v;
    std::memcpy(&v, p, sizeof v);
    return v;
}

inline void store(float* p, const v16& v, int n) {
    if (n >= 16)
        std::memcpy(p, &v, sizeof v);
    else if (n > 0)
        std::memcpy(p, &v, sizeof(float) * n);
}

inline v16 splat(float a) { return v16{} + a; }

// exp(x) in single precision (Cephes expf: range reduction by ln 2, degree-6 polynomial),
// relative error about 2e-7 for |x| < 87; clamped outside.
inline v16 exp16(v16 x) {
    x = x < splat(-87.0f) ? splat(-87.0f) : x;
    x = x > splat(88.0f) ? splat(88.0f) : x;
    const v16 magic = splat(12582912.0f);            // 1.5 * 2^23: adding it rounds to an integer
    v16 n = (x * splat(1.44269504088896341f) + magic) - magic;
    v16 r = x - n * splat(0.693359375f);
    r = r - n * splat(-2.12194440e-4f);
    v16 p = splat(1.9875691500e-4f);
    p = p * r + splat(1.3981999507e-3f);
    p = p * r + splat(8.3334519073e-3f);
    p = p * r + splat(4.1665795894e-2f);
    p = p * r + splat(1.6666665459e-1f);
    p = p * r + splat(5.0000001201e-1f);
    p = p * r * r + r + splat(1.0f);
    i16 bits = (__builtin_convertvector(n, i16) + 127) << 23;
    v16 scale;
    std::memcpy(&scale, &bits, sizeof scale);
    return p * scale;
}

inline v16 activate(v16 z, int activation) {
    if (activation == 1)   // tanh z = 1 - 2 / (exp(2 z) + 1)
        return splat(1.0f) - splat(2.0f) / (exp16(z + z) + splat(1.0f));
    if (activation == 2)   // sigmoid
        return splat(1.0f) / (splat(1.0f) + exp16(-z));
    return z;
}

// The orbit sums of one channel at 16 pixels starting at p (a pointer into a padded image
// with row stride wp), in the order (a, b), 0 <= a <= b <= R, of ifenn.network.orbit.
template <int R>
inline void orbit_sums(const float* p, int wp, v16* out) {
    v16 t[R + 1][2 * R + 1];
    for (int dx = -R; dx <= R; ++dx) t[0][dx + R] = load(p + dx);
    for (int a = 1; a <= R; ++a)
        for (int dx = -R; dx <= R; ++dx) t[a][dx + R] = load(p - a * wp + dx) + load(p + a * wp + dx);
    int k = 0;
    for (int a = 0; a <= R; ++a)
        for (int b = a; b <= R; ++b) {
            v16 s = b == 0 ? t[a][R] : t[a][R - b] + t[a][R + b];
            if (a != b) s += a == 0 ? t[b][R] : t[b][R - a] + t[b][R + a];
            out[k++] = s;
        }
}

// outputs o0 .. o0 + OB of one chunk of P vectors: the product of OB weight rows with the
// chunk's sums, activated, the first n pixels stored
template <int OB, int P>
inline void product(const v16* sums, int k_total, const float* w, int o0, int activation, float* y, int plane, int n) {
    v16 acc[OB][P] = {};
    const float* wo = w + static_cast<int64_t>(o0) * k_total;
    for (int j = 0; j < k_total; ++j) {
        v16 s[P];
        for (int v = 0; v < P; ++v) s[v] = sums[j * P + v];
        for (int ob = 0; ob < OB; ++ob) {
            const float weight = wo[ob * k_total + j];
            for (int v = 0; v < P; ++v) acc[ob][v] += weight * s[v];
        }
    }
    for (int ob = 0; ob < OB; ++ob) {
        float* out = y + static_cast<int64_t>(o0 + ob) * plane;
        for (int v = 0; v < P; ++v) store(out + 16 * v, activate(acc[ob][v], activation), n - 16 * v);
    }
}

template <int R>
struct Layer {
    static constexpr int NF = (R + 1) * (R + 2) / 2;
    const float* x;
    int c_in, ny, nx;
    float* y;
    int c_out;
    const float* w;
    int activation;
    int wp, plane, k_total;
    std::vector<v16> sums;

    Layer(const float* x_, int c_in_, int ny_, int nx_, float* y_, int c_out_, const float* w_, int activation_)
        : x(x_), c_in(c_in_), ny(ny_), nx(nx_), y(y_), c_out(c_out_), w(w_), activation(activation_),
          wp(nx_ + 2 * R), plane((ny_ + 2 * R) * (nx_ + 2 * R)), k_total(NF * c_in_),
          sums(static_cast<size_t>(NF * c_in_) * PV) {}

    // n <= 16 P pixels from image pixel (row, x0) on
    template <int P>
    void chunk(int row, int x0, int n) {
        v16 tmp[NF];
        const int64_t offset = static_cast<int64_t>(row + R) * wp + x0 + R;
        for (int i = 0; i < c_in; ++i)
            for (int v = 0; v < P; ++v) {
                orbit_sums<R>(x + static_cast<int64_t>(i) * plane + offset + 16 * v, wp, tmp);
                for (int k = 0; k < NF; ++k) sums[(k * c_in + i) * P + v] = tmp[k];
            }
        float* out = y + offset;
        int o = 0;
        for (; o + 12 <= c_out; o += 12) product<12, P>(sums.data(), k_total, w, o, activation, out, plane, n);
        for (; o + 4 <= c_out; o += 4) product<4, P>(sums.data(), k_total, w, o, activation, out, plane, n);
        for (; o < c_out; ++o) product<1, P>(sums.data(), k_total, w, o, activation, out, plane, n);
    }

    void run(int row, int first, int end) {
        int x0 = first;
        for (; x0 + 16 < end; x0 += CHUNK) chunk<PV>(row, x0, std::min(CHUNK, end - x0));
        if (x0 < end) chunk<1>(row, x0, end - x0);
    }
};

// every run of nonzero pixels of a (h, w) mask whose pixel (0, 0) is image pixel (y0, x0);
// runs less than a vector apart are taken as one (the pixels between are recomputed from the
// current inputs: the same values or fresher ones, at no extra cost)
template <int R>
void layer_on_mask(Layer<R>& layer, const uint8_t* mask, int h, int w, int y0, int x0) {
    for (int i = 0; i < h; ++i) {
        const uint8_t* m = mask + static_cast<int64_t>(i) * w;
        int j = 0, first = -1, end = -1;
        while (j < w) {
            while (j < w && !m[j]) ++j;
            if (j == w) break;
            const int start = j;
            while (j < w && m[j]) ++j;
            if (first >= 0 && start - end < 16) {
                end = j;
                continue;
            }
            if (first >= 0) layer.run(y0 + i, x0 + first, x0 + end);
            first = start;
            end = j;
        }
        if (first >= 0) layer.run(y0 + i, x0 + first, x0 + end);
    }
}

template <int R>
void layer(const float* x, int c_in, int ny, int nx, float* y, int c_out, const float* w,
           const uint8_t* mask, int h, int mw, int y0, int x0, int activation) {
    Layer<R> layer(x, c_in, ny, nx, y, c_out, w, activation);
    layer_on_mask(layer, mask, h, mw, y0, x0);
}

// out[o] = 1 where some in[j] != 0 with |j - o| <= r, 0 <= j < n
void dilate_row(const uint8_t* in, uint8_t* out, int n, int r) {
    int last = -r - 1;   // the last nonzero position <= i
    for (int i = 0; i < n + r; ++i) {
        if (i < n && in[i]) last = i;
        if (i >= r) out[i - r] = last >= i - 2 * r;
    }
}

}  // namespace

extern "C" {

// y = activation(layer(x)) at the nonzero pixels of ``mask`` (h, w), whose pixel (0, 0) is
// image pixel (y0, x0). Returns 0, or -1 for a kernel radius not instantiated here.
int ifenn_orbit_layer(const float* x, int c_in, int ny, int nx, int radius, float* y, int c_out,
                      const float* w, const uint8_t* mask, int h, int mw, int y0, int x0, int activation) {
    switch (radius) {
        case 1: layer<1>(x, c_in, ny, nx, y, c_out, w, mask, h, mw, y0, x0, activation); return 0;
        case 2: layer<2>(x, c_in, ny, nx, y, c_out, w, mask, h, mw, y0, x0, activation); return 0;
        case 3: layer<3>(x, c_in, ny, nx, y, c_out, w, mask, h, mw, y0, x0, activation); return 0;
        default: return -1;
    }
}

// out (h, w) = in grown by r pixels in a square window; tmp: h * w bytes of scratch
void ifenn_dilate(const uint8_t* in, uint8_t* out, uint8_t* tmp, int h, int w, int r) {
    for (int i = 0; i < h; ++i) dilate_row(in + static_cast<int64_t>(i) * w, tmp + static_cast<int64_t>(i) * w, w, r);
    for (int i = 0; i < h; ++i) {
        uint8_t* o = out + static_cast<int64_t>(i) * w;
        std::memset(o, 0, w);
        for (int k = std::max(0, i - r); k <= std::min(h - 1, i + r); ++k) {
            const uint8_t* t = tmp + static_cast<int64_t>(k) * w;
            for (int j = 0; j < w; ++j) o[j] |= t[j];
        }
    }
}

}  // extern "C"

namespace {

// ---------------------------------------------------------------------------------------------
// Conjugate gradients preconditioned by one multigrid V-cycle, for the correction of the pixel
// equation on an n x m box (ifenn/pixel_equation/numpy_backend.py, PixelEquation.solve_box):
//
//     A delta = rhs,   (A x)_i = (a_i + 3 D) x_i - D (0.5 sum_edges x_j + 0.25 sum_corners x_j),
//
// a = a0 + 2 H, with x = 0 beyond a side of the box that lies inside the image (Dirichlet data:
// the values around the box stay) and x replicated beyond a side on the image edge (the
// "replicate" padding, zero flux); ``replicate`` holds the four sides' flags (bottom = row 0, top,
// left = column 0, right). Stops when max_i |r_i| / a_i <= target (the certificate of the module
// doc) and returns the iterations (-1: not reached in maxiter); *worst gets the max reached.
//
// The V-cycle (cell-centred, 2 x 2 agglomeration): undamped Jacobi smoothing (2 sweeps before
// and after; for this 9-point stencil the high-frequency eigenvalues of D^-1 A lie in [2/3, 4/3],
// so plain Jacobi damps them by 1/3 or more), bilinear prolongation, restriction = its transpose
// / 4 (the preconditioner is symmetric positive definite, as CG needs), coarse operators
// re-discretised (D / 4 per level, a averaged over the children, the slits' links at that level's
// spacing cut), Jacobi sweeps on the coarsest.
// the V-cycle is a preconditioner: single precision halves its memory traffic (the CG around
// it, the residuals and the certificate stay in double)
using real = float;

struct MGLevel {
    int n, m;
    real D = 0;
    bool rep[4];                       // bottom, top, left, right: replicate (true) or zero ghosts
    std::vector<real> a;             // a, n x m
    std::vector<real> diag, inv;     // a + 3 D and its inverse, n x m
    std::vector<real> x, y;          // (n + 2) x (m + 2), padded (y: the Jacobi sweeps' second buffer)
    std::vector<real> b, r;          // n x m
    // bilinear transfer to the next coarser level, per direction: fine index -> two coarse
    // indices and weights (a ghost folded onto the edge or dropped; weight 0 when dropped)
    std::vector<int> row_c, col_c;
    std::vector<real> row_w, col_w;
    std::vector<real> tmp;           // coarse rows x fine columns
    // the level's slit cuts (links i -> j, flat in the level; j = -1 beyond the box): its
    // smoother and residual use the cut operator; set for the duration of one call
    int n_cut = 0;
    const int* cut_rows = nullptr;
    const int* cut_cols = nullptr;
    const double* cut_w = nullptr;
};

// out_i -= scale_i D w x_j over the cut links i -> j (x padded, out n x m or padded by one):
// once the diagonal is the cut one, (A_cut x)_i = mg_row(diag_cut) + D sum w x_j
inline void mg_cut_subtract(const MGLevel& L, const real* x, real* out, const real* scale, bool padded_out) {
    const int64_t w = L.m + 2;
    for (int k = 0; k < L.n_cut; ++k) {
        const int i = L.cut_rows[k], j = L.cut_cols[k];
        const real xj = j >= 0 ? x[(j / L.m + 1) * w + j % L.m + 1] : real(0);
        const int64_t o = padded_out ? (i / L.m + 1) * w + i % L.m + 1 : i;
        out[o] -= (scale ? scale[i] : real(1)) * real(L.D * L.cut_w[k]) * xj;
    }
}

// the ghosts of a padded vector on L's box (single for the V-cycle, double for the CG)
template <class T>
inline void mg_ghosts(const MGLevel& L, T* x) {
    const int n = L.n, m = L.m;
    const int64_t w = m + 2;
    for (int j = 1; j <= m; ++j) {
        x[j] = L.rep[0] ? x[w + j] : 0.0;
        x[(n + 1) * w + j] = L.rep[1] ? x[n * w + j] : 0.0;
    }
    for (int i = 0; i <= n + 1; ++i) {
        x[i * w] = L.rep[2] ? x[i * w + 1] : 0.0;
        x[i * w + m + 1] = L.rep[3] ? x[i * w + m] : 0.0;
    }
}

// (A x)_j of one row (x padded, ghosts filled; d = a + 3 D): single for the V-cycle, double for the CG
template <class T>
inline T mg_row(const T* up, const T* mid, const T* down, int j, T d, T D) {
    const T edge = mid[j] + mid[j + 2] + up[j + 1] + down[j + 1];
    const T corner = up[j] + up[j + 2] + down[j] + down[j + 2];
    return d * mid[j + 1] - D * (T(0.5) * edge + T(0.25) * corner);
}

// y = b - A x
void mg_residual(const MGLevel& L, const real* x, const real* b, real* y) {
    const int n = L.n, m = L.m;
    const int64_t w = m + 2;
    for (int i = 0; i < n; ++i) {
        const real* up = x + i * w;
        const real* d = L.diag.data() + static_cast<int64_t>(i) * m;
        const real* bb = b + static_cast<int64_t>(i) * m;
        real* o = y + static_cast<int64_t>(i) * m;
        for (int j = 0; j < m; ++j) o[j] = bb[j] - mg_row(up, up + w, up + 2 * w, j, d[j], L.D);
    }
    mg_cut_subtract(L, x, y, nullptr, false);
}

// ``sweeps`` Jacobi sweeps x += D^-1 (b - A x), each one pass into the second buffer; from x = 0
// the first is x = D^-1 b. Leaves x's ghosts filled.
void mg_jacobi(MGLevel& L, int sweeps, bool from_zero) {
    const int n = L.n, m = L.m;
    const int64_t w = m + 2;
    int done = 0;
    if (from_zero) {
        for (int i = 0; i < n; ++i) {
            real* xi = L.x.data() + (i + 1) * w + 1;
            const real* bi = L.b.data() + static_cast<int64_t>(i) * m;
            const real* vi = L.inv.data() + static_cast<int64_t>(i) * m;
            for (int j = 0; j < m; ++j) xi[j] = bi[j] * vi[j];
        }
        done = 1;
    }
    mg_ghosts(L, L.x.data());
    for (; done < sweeps; ++done) {
        const real* x = L.x.data();
        for (int i = 0; i < n; ++i) {
            const real* up = x + i * w;
            const real* d = L.diag.data() + static_cast<int64_t>(i) * m;
            const real* vi = L.inv.data() + static_cast<int64_t>(i) * m;
            const real* bi = L.b.data() + static_cast<int64_t>(i) * m;
            real* yi = L.y.data() + (i + 1) * w + 1;
            for (int j = 0; j < m; ++j) yi[j] = up[w + j + 1] + vi[j] * (bi[j] - mg_row(up, up + w, up + 2 * w, j, d[j], L.D));
        }
        mg_cut_subtract(L, L.x.data(), L.y.data(), L.inv.data(), true);  // x: before the sweep
        std::swap(L.x, L.y);
        mg_ghosts(L, L.x.data());
    }
}

// cell-centred bilinear interpolation in one direction: fine i takes 3/4 of its parent i / 2
// and 1/4 of the parent's neighbour towards i; a neighbour beyond the edge is the parent
// itself (replicate) or zero (dropped)
void mg_transfer(int nf, int nc, bool rep_low, bool rep_high, std::vector<int>& idx, std::vector<real>& wgt) {
    idx.assign(2 * nf, 0);
    wgt.assign(2 * nf, 0.0);
    for (int i = 0; i < nf; ++i) {
        const int p = i / 2, q = (i % 2 == 0) ? p - 1 : p + 1;
        idx[2 * i] = p, wgt[2 * i] = 0.75;
        if (q >= 0 && q < nc) {
            idx[2 * i + 1] = q, wgt[2 * i + 1] = 0.25;
        } else if ((q < 0 && rep_low) || (q >= nc && rep_high)) {
            wgt[2 * i] = 1.0;
            idx[2 * i + 1] = p;
        } else {
            idx[2 * i + 1] = p;  // weight 0
        }
    }
}

void mg_restrict(MGLevel& F, MGLevel& C) {  // C.b = P^T F.r / 4, separably
    const int mf = F.m, mc = C.m;
    std::fill(F.tmp.begin(), F.tmp.end(), 0.0);
    for (int i = 0; i < F.n; ++i) {
        const real* ri = F.r.data() + static_cast<int64_t>(i) * mf;
        for (int k = 0; k < 2; ++k) {
            const real wk = 0.25f * F.row_w[2 * i + k];
            if (wk == 0.0) continue;
            real* t = F.tmp.data() + static_cast<int64_t>(F.row_c[2 * i + k]) * mf;
            for (int j = 0; j < mf; ++j) t[j] += wk * ri[j];
        }
    }
    std::fill(C.b.begin(), C.b.end(), 0.0);
    for (int I = 0; I < C.n; ++I) {
        const real* t = F.tmp.data() + static_cast<int64_t>(I) * mf;
        real* out = C.b.data() + static_cast<int64_t>(I) * mc;
        for (int j = 0; j < mf; ++j) {
            out[F.col_c[2 * j]] += F.col_w[2 * j] * t[j];
            out[F.col_c[2 * j + 1]] += F.col_w[2 * j + 1] * t[j];
        }
    }
}

void mg_prolong_add(MGLevel& F, const MGLevel& C) {  // F.x += P C.x, separably
    const int mc = C.m;
    const int64_t wc = mc + 2, wf = F.m + 2;
    const real* xc = C.x.data();
    for (int I = 0; I < C.n; ++I) {  // tmp (coarse rows x fine columns) = C.x P_x^T
        const real* row = xc + (I + 1) * wc + 1;
        real* t = F.tmp.data() + static_cast<int64_t>(I) * F.m;
        for (int j = 0; j < F.m; ++j) t[j] = F.col_w[2 * j] * row[F.col_c[2 * j]] + F.col_w[2 * j + 1] * row[F.col_c[2 * j + 1]];
    }
    for (int i = 0; i < F.n; ++i) {
        const real* t0 = F.tmp.data() + static_cast<int64_t>(F.row_c[2 * i]) * F.m;
        const real* t1 = F.tmp.data() + static_cast<int64_t>(F.row_c[2 * i + 1]) * F.m;
        const real w0 = F.row_w[2 * i], w1 = F.row_w[2 * i + 1];
        real* xi = F.x.data() + (i + 1) * wf + 1;
        for (int j = 0; j < F.m; ++j) xi[j] += w0 * t0[j] + w1 * t1[j];
    }
}

#ifndef MG_SMOOTH_VALUE
#define MG_SMOOTH_VALUE 2
#endif
constexpr int MG_SMOOTH = MG_SMOOTH_VALUE;
constexpr int MG_COARSEST_SWEEPS = 30;

void mg_vcycle(std::vector<MGLevel>& levels, size_t k) {  // levels[k].x from levels[k].b
    MGLevel& L = levels[k];
    if (k + 1 == levels.size()) {
        mg_jacobi(L, MG_COARSEST_SWEEPS, true);
        return;
    }
    mg_jacobi(L, MG_SMOOTH, true);
    mg_residual(L, L.x.data(), L.b.data(), L.r.data());
    mg_restrict(L, levels[k + 1]);
    mg_vcycle(levels, k + 1);
    mg_prolong_add(L, levels[k + 1]);
    mg_jacobi(L, MG_SMOOTH, false);  // as many sweeps after as before: a symmetric V-cycle
}

// The levels and CG vectors of one box shape, kept between calls: a correction runs every
// increment on boxes of few shapes, and fresh buffers would cost their page faults each time
// (about as much as the solve at 600 x 600).
struct MGWork {
    int n, m, rep[4];
    std::vector<MGLevel> levels;
    std::vector<double> r, z, q, p, inv_a, diag;
};

MGWork& mg_work(int n, int m, const int* replicate) {
    static std::vector<std::unique_ptr<MGWork>> cache;
    for (auto& work : cache)
        if (work->n == n && work->m == m && std::equal(replicate, replicate + 4, work->rep)) return *work;
    if (cache.size() >= 8) cache.erase(cache.begin());  // the oldest shape goes
    auto work = std::make_unique<MGWork>();
    work->n = n, work->m = m;
    std::copy(replicate, replicate + 4, work->rep);
    std::vector<MGLevel>& levels = work->levels;
    levels.resize(1);
    levels[0].n = n, levels[0].m = m;
    for (int s = 0; s < 4; ++s) levels[0].rep[s] = replicate[s] != 0;
    while (levels.back().n > 4 && levels.back().m > 4 && levels.size() < 16) {
        MGLevel C;
        C.n = (levels.back().n + 1) / 2, C.m = (levels.back().m + 1) / 2;
        for (int s = 0; s < 4; ++s) C.rep[s] = levels.back().rep[s];
        levels.push_back(std::move(C));
    }
    for (size_t k = 0; k < levels.size(); ++k) {
        MGLevel& L = levels[k];
        const size_t size = static_cast<size_t>(L.n) * L.m;
        L.a.assign(size, 0.0), L.diag.assign(size, 0.0), L.inv.assign(size, 0.0);
        L.x.assign(static_cast<size_t>(L.n + 2) * (L.m + 2), 0.0), L.y = L.x;
        L.b.assign(size, 0.0), L.r.assign(size, 0.0);
        if (k + 1 < levels.size()) {
            const MGLevel& C = levels[k + 1];
            mg_transfer(L.n, C.n, L.rep[0], L.rep[1], L.row_c, L.row_w);
            mg_transfer(L.m, C.m, L.rep[2], L.rep[3], L.col_c, L.col_w);
            L.tmp.assign(static_cast<size_t>(C.n) * L.m, 0.0);
        }
    }
    const size_t size = static_cast<size_t>(n) * m;
    work->r.assign(size, 0.0), work->z.assign(size, 0.0), work->q.assign(size, 0.0), work->inv_a.assign(size, 0.0);
    work->diag.assign(size, 0.0);
    work->p.assign(static_cast<size_t>(n + 2) * (m + 2), 0.0);
    cache.push_back(std::move(work));
    return *cache.back();
}

// the coefficients of every level for this a: coarse a = the mean of its (up to 4) children
void mg_coefficients(MGWork& work, const double* a, double D) {
    std::vector<MGLevel>& levels = work.levels;
    const size_t size = static_cast<size_t>(work.n) * work.m;
    for (size_t c = 0; c < size; ++c) {
        levels[0].a[c] = static_cast<real>(a[c]);
        work.diag[c] = a[c] + 3.0 * D;
        work.inv_a[c] = 1.0 / a[c];
    }
    double level_D = D;
    levels[0].D = static_cast<real>(D);
    for (size_t k = 1; k < levels.size(); ++k) {
        const MGLevel& F = levels[k - 1];
        MGLevel& C = levels[k];
        level_D /= 4.0;
        C.D = static_cast<real>(level_D);
        for (int I = 0; I < C.n; ++I) {
            const int i0 = 2 * I, i1 = std::min(2 * I + 1, F.n - 1);
            const real* f0 = F.a.data() + static_cast<size_t>(i0) * F.m;
            const real* f1 = F.a.data() + static_cast<size_t>(i1) * F.m;
            real* c = C.a.data() + static_cast<size_t>(I) * C.m;
            for (int J = 0; J < C.m; ++J) {
                const int j0 = 2 * J, j1 = std::min(2 * J + 1, F.m - 1);
                c[J] = real(0.25) * (f0[j0] + f0[j1] + f1[j0] + f1[j1]);  // an odd edge counts its last row / column twice
            }
        }
    }
    for (MGLevel& L : levels)
        for (size_t c = 0; c < L.a.size(); ++c) L.diag[c] = L.a[c] + real(3) * L.D, L.inv[c] = real(1) / L.diag[c];
    for (MGLevel& L : levels) {  // the cut links leave each level's diagonal
        for (int k = 0; k < L.n_cut; ++k) L.diag[L.cut_rows[k]] -= real(L.D * L.cut_w[k]);
        for (int k = 0; k < L.n_cut; ++k) L.inv[L.cut_rows[k]] = real(1) / L.diag[L.cut_rows[k]];
    }
}

}  // namespace

extern "C" {

// The residual R = a c - D (K9*(c) - 3 c) - 2 H of the pixel equation (normalised: R / a) on the
// box [r0, r1) x [c0, c1) of an ny x nx image, read from the image itself: neighbours beyond the
// image edge are the edge's values (replicate = 1: zero flux) or zero. out has the box's shape.
void ifenn_pixel_residual(const double* phi, const double* history, double* out, int ny, int nx, int r0, int r1, int c0, int c1,
                          double a0, double D, int replicate, int normalised) {
    std::vector<double> zeros(static_cast<size_t>(nx) + 2, 0.0), rows[3];
    for (auto& row : rows) row.assign(static_cast<size_t>(nx) + 2, 0.0);
    const int m = c1 - c0;
    for (int i = r0; i < r1; ++i) {
        // the three image rows around i, each with a one-pixel frame (the padding)
        for (int k = 0; k < 3; ++k) {
            int source = i + k - 1;
            double* row = rows[k].data();
            if (source < 0 || source >= ny) {
                if (!replicate) {
                    std::fill(rows[k].begin(), rows[k].end(), 0.0);
                    continue;
                }
                source = source < 0 ? 0 : ny - 1;
            }
            const double* image = phi + static_cast<int64_t>(source) * nx;
            const int lo = std::max(c0 - 1, 0), hi = std::min(c1 + 1, nx);
            std::copy(image + lo, image + hi, row + lo + 1);
            row[0] = replicate ? image[0] : 0.0;
            row[nx + 1] = replicate ? image[nx - 1] : 0.0;
        }
        const double* up = rows[0].data() + c0;  // index j - c0 + 1 is column j
        const double* mid = rows[1].data() + c0;
        const double* down = rows[2].data() + c0;
        const double* h = history + static_cast<int64_t>(i) * nx + c0;
        double* o = out + static_cast<int64_t>(i - r0) * m;
        for (int j = 0; j < m; ++j) {
            const double c = mid[j + 1];
            const double edge = mid[j] + mid[j + 2] + up[j + 1] + down[j + 1];
            const double corner = up[j] + up[j + 2] + down[j] + down[j + 2];
            const double a = a0 + 2.0 * h[j];
            const double R = a * c - D * (0.5 * edge + 0.25 * corner - 3.0 * c) - 2.0 * h[j];
            o[j] = normalised ? R / a : R;
        }
    }
}

// Slits (ifenn.pixels.SlitCuts): n_cut directed links i -> j of the box (flat indices; j = -1:
// beyond the box, where delta is 0) that carry no flux: (A x)_i += D w (x_j - x_i) for each. The
// CG's operator and so its residual and certificate are the cut ones; so are the V-cycle's
// Jacobi smoothers and residuals (diagonal and links) on every level: level_cuts[k] links of level
// k, one after another in cut_rows / cut_cols / cut_w (level 0 first: the finest, the CG's; the
// coarse levels' from the slits at their own spacing, so a cut stays a cut there). Levels beyond
// n_levels have none (a symmetric positive definite preconditioner all the same).
int ifenn_pixel_mg_pcg(const double* rhs, const double* a, double* delta, int n, int m, double D, const int* replicate,
                       double target, int maxiter, double* worst, int n_levels, const int* level_cuts, const int* cut_rows,
                       const int* cut_cols, const double* cut_w) {
    MGWork& work = mg_work(n, m, replicate);
    std::vector<MGLevel>& levels = work.levels;
    MGLevel& top = levels[0];
    int64_t offset = 0;
    for (int k = 0; k < n_levels && k < static_cast<int>(levels.size()); ++k) {
        MGLevel& L = levels[k];
        L.n_cut = level_cuts[k], L.cut_rows = cut_rows + offset, L.cut_cols = cut_cols + offset, L.cut_w = cut_w + offset;
        offset += level_cuts[k];
    }
    const int n_cut = top.n_cut;
    struct Unset {  // the work is cached per shape: forget this call's cuts on every return
        std::vector<MGLevel>& levels;
        ~Unset() {
            for (MGLevel& L : levels) L.n_cut = 0, L.cut_rows = L.cut_cols = nullptr, L.cut_w = nullptr;
        }
    } unset{levels};
    mg_coefficients(work, a, D);
    const int64_t w = m + 2;
    double *r = work.r.data(), *z = work.z.data(), *q = work.q.data(), *p = work.p.data();
    const double* inv_a = work.inv_a.data();
    const double* diag = work.diag.data();
    // the loops below fuse what they can and keep four partial sums: a single running sum would
    // serialise the additions (no reassociation without -ffast-math), and these vectors are
    // streamed once per pass
    double most = 0.0;
    for (int64_t c = 0; c < static_cast<int64_t>(n) * m; ++c) {
        r[c] = rhs[c];
        delta[c] = 0.0;
        most = std::max(most, std::abs(r[c]) * inv_a[c]);
    }
    *worst = most;
    if (*worst <= target) return 0;
    // z = M r (one V-cycle) and r . z
    auto precondition = [&]() {
        for (int64_t c = 0; c < static_cast<int64_t>(n) * m; ++c) top.b[c] = static_cast<real>(r[c]);
        mg_vcycle(levels, 0);
        double sums[4] = {0.0, 0.0, 0.0, 0.0};
        for (int i = 0; i < n; ++i) {
            const real* x = top.x.data() + (i + 1) * w + 1;
            double* zi = z + static_cast<int64_t>(i) * m;
            const double* ri = r + static_cast<int64_t>(i) * m;
            int j = 0;
            for (; j + 4 <= m; j += 4)
                for (int k = 0; k < 4; ++k) zi[j + k] = x[j + k], sums[k] += ri[j + k] * zi[j + k];
            for (; j < m; ++j) zi[j] = x[j], sums[0] += ri[j] * zi[j];
        }
        return (sums[0] + sums[1]) + (sums[2] + sums[3]);
    };
    double rz = precondition();
    for (int i = 0; i < n; ++i) std::copy(z + static_cast<int64_t>(i) * m, z + static_cast<int64_t>(i + 1) * m, p + (i + 1) * w + 1);
    for (int iteration = 1; iteration <= maxiter; ++iteration) {
        // q = A p and p . q
        mg_ghosts(top, p);
        double sums[4] = {0.0, 0.0, 0.0, 0.0};
        for (int i = 0; i < n; ++i) {
            const double* up = p + i * w;
            const double* mid = up + w;
            const double* down = mid + w;
            const double* d = diag + static_cast<int64_t>(i) * m;
            double* o = q + static_cast<int64_t>(i) * m;
            for (int j = 0; j < m; ++j) {
                o[j] = mg_row(up, mid, down, j, d[j], D);
                sums[j & 3] += mid[j + 1] * o[j];
            }
        }
        for (int k = 0; k < n_cut; ++k) {
            const int i = cut_rows[k], j = cut_cols[k];
            const double pi = p[(i / m + 1) * w + i % m + 1];
            const double pj = j >= 0 ? p[(j / m + 1) * w + j % m + 1] : 0.0;
            const double change = D * cut_w[k] * (pj - pi);
            q[i] += change;
            sums[0] += pi * change;
        }
        const double alpha = rz / ((sums[0] + sums[1]) + (sums[2] + sums[3]));
        // delta += alpha p, r -= alpha q, and the certificate's max |r| / a
        double largest[4] = {0.0, 0.0, 0.0, 0.0};
        for (int i = 0; i < n; ++i) {
            const double* pi = p + (i + 1) * w + 1;
            const int64_t row = static_cast<int64_t>(i) * m;
            int j = 0;
            for (; j + 4 <= m; j += 4)
                for (int k = 0; k < 4; ++k) {
                    const int64_t c = row + j + k;
                    delta[c] += alpha * pi[j + k];
                    r[c] -= alpha * q[c];
                    largest[k] = std::max(largest[k], std::abs(r[c]) * inv_a[c]);
                }
            for (; j < m; ++j) {
                const int64_t c = row + j;
                delta[c] += alpha * pi[j];
                r[c] -= alpha * q[c];
                largest[0] = std::max(largest[0], std::abs(r[c]) * inv_a[c]);
            }
        }
        *worst = std::max(std::max(largest[0], largest[1]), std::max(largest[2], largest[3]));
        if (*worst <= target) return iteration;
        const double rz_new = precondition();
        const double beta = rz_new / rz;
        rz = rz_new;
        for (int i = 0; i < n; ++i) {
            double* pi = p + (i + 1) * w + 1;
            const double* zi = z + static_cast<int64_t>(i) * m;
            for (int j = 0; j < m; ++j) pi[j] = zi[j] + beta * pi[j];
        }
    }
    return -1;
}

int ifenn_kernel_version() { return 8; }

}
