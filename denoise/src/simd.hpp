#pragma once
// A minimal SIMD float type for the denoiser's inner loops (one width, as
// Embree picks per target: 4 = SSE2, the x86-64 baseline). Built
// on GCC/Clang vector extensions, so every operation is lane-wise IEEE
// arithmetic: a lane's result is the same as the scalar code's would be
// (the project compiles in ISO mode, where floating-point contraction into
// FMA is off), and the output does not depend on which lanes share a vector.
#include <cstddef>
#include <cstdint>
#include <cmath>
#include <cstring>

namespace rtlab::denoise::simd {

// (GCC ignores a vector_size that depends on a template parameter, so the
// width is fixed here rather than templated.)
inline constexpr int kWidth = 4;
typedef float vf __attribute__((vector_size(kWidth * sizeof(float))));
typedef std::int32_t vi __attribute__((vector_size(kWidth * sizeof(std::int32_t))));

// Unaligned vectors of float: loads and stores through this type are float
// accesses (type-based alias analysis applies), unlike memcpy, which the
// compiler must assume may overwrite any pointer it holds.
typedef float vfUnaligned __attribute__((vector_size(kWidth * sizeof(float)), aligned(alignof(float))));

inline vf splat(float v) { return vf{} + v; }
inline vf loadu(const float* p) { return *reinterpret_cast<const vfUnaligned*>(p); }
inline void storeu(float* p, const vf& v) { *reinterpret_cast<vfUnaligned*>(p) = v; }
// Loads `count` (< kWidth) lanes, the rest `fill`.
inline vf loadPartial(const float* p, int count, float fill) {
    vf v = splat(fill);
    for (int k = 0; k < count; ++k) v[k] = p[k];
    return v;
}
inline void storePartial(float* p, const vf& v, int count) {
    for (int k = 0; k < count; ++k) p[k] = v[k];
}

inline vf select(const vi& mask, const vf& a, const vf& b) { return mask ? a : b; }
inline vf abs(const vf& v) {
    vi bits;
    std::memcpy(&bits, &v, sizeof(v));
    bits &= 0x7fffffff;
    vf out;
    std::memcpy(&out, &bits, sizeof(v));
    return out;
}
// max(v, 0), NaN -> 0.
inline vf positiveOrZero(const vf& v) { return select(v > 0.f, v, splat(0.f)); }
inline vf min(const vf& a, const vf& b) { return select(a < b, a, b); }

// 2^f for f in [-126, 0] (smaller f gives 0): 2^round(f) from the exponent
// bits times the degree-6 Taylor polynomial of 2^t, t = f - round(f) in
// [-1/2, 1/2] (relative error < 2e-7).
inline vf exp2NonPositive(const vf& f) {
    const vi tooSmall = f < -126.f;
    const vf fc = select(tooSmall, splat(-126.f), f);
    const vf shifted = fc + 0.5f;                   // <= 0.5
    vi i = __builtin_convertvector(shifted, vi);    // truncation toward 0
    const vi adjust = __builtin_convertvector(i, vf) > shifted;
    i += adjust;                                    // floor: true lanes are -1
    const vf t = fc - __builtin_convertvector(i, vf);
    vf p = splat(1.540353039e-4f);                  // ln2^6 / 6!
    p = p * t + 1.333355815e-3f;                    // ln2^5 / 5!
    p = p * t + 9.618129108e-3f;                    // ln2^4 / 4!
    p = p * t + 5.550410866e-2f;                    // ln2^3 / 3!
    p = p * t + 2.402265070e-1f;                    // ln2^2 / 2!
    p = p * t + 6.931471806e-1f;                    // ln2
    p = p * t + 1.f;
    const vi bits = (i + 127) << 23;
    vf scale;
    std::memcpy(&scale, &bits, sizeof(scale));
    return select(tooSmall, splat(0.f), p * scale);
}

// exp(-e) for e >= 0 (negative e counts as 0; NaN and e >= 87 give 0).
inline vf expNeg(const vf& e) {
    const vi huge = !(e < 87.f);  // and NaN
    const vf ec = positiveOrZero(e);
    return select(huge, splat(0.f), exp2NonPositive(ec * -1.44269504089f));
}

// log2(x) for x > 0 finite (others are the caller's business): exponent plus
// a polynomial in the mantissa m in [sqrt(1/2), sqrt(2)) (abs error < 1e-6).
inline vf log2Positive(const vf& x) {
    vi bits;
    std::memcpy(&bits, &x, sizeof(x));
    vi e = ((bits >> 23) & 0xff) - 127;
    vi mbits = (bits & 0x007fffff) | 0x3f800000;  // mantissa in [1, 2)
    vf m;
    std::memcpy(&m, &mbits, sizeof(m));
    const vi big = m > 1.41421356f;
    m = select(big, m * 0.5f, m);
    e -= big;  // true lanes are -1: e + 1
    // log2(m) = 2/ln2 * atanh(s), s = (m - 1) / (m + 1), |s| <= 0.1716.
    const vf s = (m - 1.f) / (m + 1.f);
    const vf s2 = s * s;
    vf p = splat(1.f / 9.f);
    p = p * s2 + 1.f / 7.f;
    p = p * s2 + 1.f / 5.f;
    p = p * s2 + 1.f / 3.f;
    p = p * s2 + 1.f;
    return __builtin_convertvector(e, vf) + p * s * 2.88539008178f;
}

// The first `count` lanes 1, the rest 0 (a row's last, partial vector).
inline vf tailMask(int count) {
    vf m = splat(0.f);
    for (int lane = 0; lane < count && lane < kWidth; ++lane) m[lane] = 1.f;
    return m;
}

// max(0, d)^sigmaN for d = n.n' (clamped to [0, 1], NaN -> 0): repeated
// squaring for integer exponents up to 4096 (the paper's 128), exp2/log2
// otherwise.
struct NormalPower {
    float sigma;
    unsigned integer;
    bool isInteger;
    int squarings = -1;  // sigma = 2^squarings (the paper's 128 = 2^7), else -1
    explicit NormalPower(float sigmaN)
        : sigma(sigmaN > 0.f ? sigmaN : 0.f),
          integer(sigma <= 4096.f && std::floor(sigma) == sigma ? static_cast<unsigned>(sigma) : 0u),
          isInteger(sigma <= 4096.f && std::floor(sigma) == sigma) {
        if (isInteger && integer != 0u && (integer & (integer - 1u)) == 0u)
            for (squarings = 0; (1u << squarings) != integer; ++squarings) {}
    }
    vf operator()(vf d) const {
        d = min(positiveOrZero(d), splat(1.f));
        if (sigma == 0.f) return splat(1.f);
        if (squarings >= 0) {
            for (int k = 0; k < squarings; ++k) d *= d;
            return d;
        }
        if (isInteger) {
            vf r = splat(1.f), b = d;
            for (unsigned e = integer; e != 0u; e >>= 1u) {
                if (e & 1u) r *= b;
                b *= b;
            }
            return r;
        }
        const vf safe = select(d > 0.f, d, splat(1.f));
        const vf p = exp2NonPositive(log2Positive(safe) * sigma);
        return select(d > 0.f, select(d < 1.f, p, splat(1.f)), splat(0.f));
    }
};

}  // namespace rtlab::denoise::simd
