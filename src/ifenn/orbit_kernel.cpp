// One layer of the PICNN as orbit sums + a small matrix product, fused, on rows of pixels.
//
// Compiled at first use by ifenn/orbit_kernel.py (g++ -O3 -march=native) and called through
// ctypes. The arithmetic is that of ifenn/orbit.py (OrbitEvaluator): for every output pixel
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
#include <cstdint>
#include <cstring>
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
// with row stride wp), in the order (a, b), 0 <= a <= b <= R, of ifenn.orbit.
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

// The pixel phase-field operator of ifenn/verification.py on an n x m box, in one pass:
// out = a * c - D * (K9*(c) - 3 c) - 2 H, with c the centre of ``ext`` ((n + 2) x (m + 2),
// the box with its one-pixel frame, row-major), a = a0 + 2 H and H on the box (n x m);
// with has_rhs = 0 the -2 H term is left out (the operator alone, for the conjugate gradients).
void ifenn_pixel_operator(const double* ext, const double* history, double* out, int n, int m, double a0, double D,
                          int has_rhs) {
    const int64_t stride = m + 2;
    for (int i = 0; i < n; ++i) {
        const double* up = ext + static_cast<int64_t>(i) * stride;
        const double* mid = up + stride;
        const double* down = mid + stride;
        const double* h = history + static_cast<int64_t>(i) * m;
        double* o = out + static_cast<int64_t>(i) * m;
        for (int j = 0; j < m; ++j) {
            const double c = mid[j + 1];
            const double edge = mid[j] + mid[j + 2] + up[j + 1] + down[j + 1];
            const double corner = up[j] + up[j + 2] + down[j] + down[j + 2];
            const double a = a0 + 2.0 * h[j];
            o[j] = a * c - D * (0.5 * edge + 0.25 * corner - 3.0 * c) - (has_rhs ? 2.0 * h[j] : 0.0);
        }
    }
}

int ifenn_kernel_version() { return 3; }

}
