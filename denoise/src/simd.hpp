#pragma once
// The denoiser's SIMD helpers (abs, exp, log2, edge-stopping terms) on
// core's width-templated vfloat<N> (rtlab/core/simd.hpp): lane-wise IEEE
// arithmetic, so the 4-wide (SSE2) and 8-wide (AVX2, picked at run time)
// kernels give bit-identical images (tests/denoise/test_simd_math.cpp).
#include <rtlab/core/simd.hpp>

#include <cmath>
#include <cstddef>
#include <cstdint>

namespace rtlab::denoise::simd {

using rtlab::simd::hasAvx2;
using rtlab::simd::Lanes;
using rtlab::simd::loadu;
using rtlab::simd::select;
using rtlab::simd::splat;
using rtlab::simd::storeu;
using rtlab::simd::vfloat;
using rtlab::simd::vint;

// The widest width this CPU runs (8 with AVX2, else 4), unless a test
// forced one with overrideWidth (0 = no override; 8 is ignored without AVX2).
int preferredWidth();
void overrideWidth(int width);
// Padding (floats) the planes need after their last pixel: the widest vector.
inline constexpr int kMaxWidth = 8;

template <int N>
RTLAB_SIMD_INLINE vfloat<N> abs(const vfloat<N>& v) {
    return (vfloat<N>)((vint<N>)v & 0x7fffffff);  // vector casts reinterpret the bits
}
// max(v, 0), NaN -> 0.
template <int N>
RTLAB_SIMD_INLINE vfloat<N> positiveOrZero(const vfloat<N>& v) {
    return select<N>(v > 0.f, v, splat<N>(0.f));
}
template <int N>
RTLAB_SIMD_INLINE vfloat<N> min(const vfloat<N>& a, const vfloat<N>& b) {
    return select<N>(a < b, a, b);
}
// max(a, b) lane-wise: a > b ? a : b (b where either is NaN), one maxps when
// b is not a compile-time constant (see opaque).
template <int N>
RTLAB_SIMD_INLINE vfloat<N> max(const vfloat<N>& a, const vfloat<N>& b) {
    return select<N>(a > b, a, b);
}
// v, hidden from constant folding: max<N>(x, opaque<N>(splat<N>(0.f))) is one
// maxps, where GCC compiles a comparison with a literal into a compare and a
// mask or blend (two instructions). Hoist it out of loops.
template <int N>
RTLAB_SIMD_INLINE vfloat<N> opaque(vfloat<N> v) {
#if !defined(__clang__)  // clang (the fuzz build) folds no worse without it, and rejects "+x" for 8 lanes here
    __asm__("" : "+x"(v));
#endif
    return v;
}
// The first `count` lanes 1, the rest 0 (a row's last, partial vector).
template <int N>
RTLAB_SIMD_INLINE vfloat<N> tailMask(int count) {
    vfloat<N> m = splat<N>(0.f);
    for (int lane = 0; lane < count && lane < N; ++lane) m[lane] = 1.f;
    return m;
}

// 2^f for f in [-126, 0] (smaller f gives 0): 2^round(f) from the exponent
// bits times the degree-6 Taylor polynomial of 2^t, t = f - round(f) in
// [-1/2, 1/2] (relative error < 2e-7).
template <int N>
RTLAB_SIMD_INLINE vfloat<N> exp2NonPositive(const vfloat<N>& f) {
    const vint<N> tooSmall = f < -126.f;
    const vfloat<N> fc = select<N>(tooSmall, splat<N>(-126.f), f);
    const vfloat<N> shifted = fc + 0.5f;                    // <= 0.5
    vint<N> i = __builtin_convertvector(shifted, vint<N>);  // truncation toward 0
    const vint<N> adjust = __builtin_convertvector(i, vfloat<N>) > shifted;
    i += adjust;  // floor: true lanes are -1
    const vfloat<N> t = fc - __builtin_convertvector(i, vfloat<N>);
    vfloat<N> p = splat<N>(1.540353039e-4f);  // ln2^6 / 6!
    p = p * t + 1.333355815e-3f;              // ln2^5 / 5!
    p = p * t + 9.618129108e-3f;              // ln2^4 / 4!
    p = p * t + 5.550410866e-2f;              // ln2^3 / 3!
    p = p * t + 2.402265070e-1f;              // ln2^2 / 2!
    p = p * t + 6.931471806e-1f;              // ln2
    p = p * t + 1.f;
    const vint<N> bits = (i + 127) << 23;
    return select<N>(tooSmall, splat<N>(0.f), p * (vfloat<N>)bits);
}

// exp(-e) for e >= 0 (negative e counts as 0; NaN and e >= 87 give 0).
template <int N>
RTLAB_SIMD_INLINE vfloat<N> expNeg(const vfloat<N>& e) {
    const vint<N> huge = !(e < 87.f);  // and NaN
    const vfloat<N> ec = positiveOrZero<N>(e);
    return select<N>(huge, splat<N>(0.f), exp2NonPositive<N>(ec * -1.44269504089f));
}

// exp(-e) as expNeg, with a degree-4 polynomial for 2^t (relative error
// < 6e-5; 5.1e-5 measured): for edge-stopping weights, where that is far below what the
// weights' own heuristics decide. Same special values as expNeg.
template <int N>
RTLAB_SIMD_INLINE vfloat<N> expNegWeight(const vfloat<N>& e) {
    const vint<N> huge = !(e < 87.f);  // and NaN
    // Clamped before the conversion to integer (a huge e, masked to 0 below,
    // would convert out of int's range).
    const vfloat<N> f = min<N>(positiveOrZero<N>(e), splat<N>(87.f)) * -1.44269504089f;  // in [-125.6, 0]
    const vfloat<N> shifted = f + 0.5f;
    vint<N> i = __builtin_convertvector(shifted, vint<N>);
    i += __builtin_convertvector(i, vfloat<N>) > shifted;  // floor
    const vfloat<N> t = f - __builtin_convertvector(i, vfloat<N>);
    vfloat<N> p = splat<N>(9.618129108e-3f);  // ln2^4 / 4!
    p = p * t + 5.550410866e-2f;              // ln2^3 / 3!
    p = p * t + 2.402265070e-1f;              // ln2^2 / 2!
    p = p * t + 6.931471806e-1f;              // ln2
    p = p * t + 1.f;
    const vint<N> bits = (i + 127) << 23;
    return select<N>(huge, splat<N>(0.f), p * (vfloat<N>)bits);
}

// log2(x) for x > 0 finite (others are the caller's business): exponent plus
// a polynomial in the mantissa m in [sqrt(1/2), sqrt(2)) (abs error < 1e-6).
template <int N>
RTLAB_SIMD_INLINE vfloat<N> log2Positive(const vfloat<N>& x) {
    const vint<N> bits = (vint<N>)x;
    vint<N> e = ((bits >> 23) & 0xff) - 127;
    const vint<N> mbits = (bits & 0x007fffff) | 0x3f800000;  // mantissa in [1, 2)
    vfloat<N> m = (vfloat<N>)mbits;
    const vint<N> big = m > 1.41421356f;
    m = select<N>(big, m * 0.5f, m);
    e -= big;  // true lanes are -1: e + 1
    // log2(m) = 2/ln2 * atanh(s), s = (m - 1) / (m + 1), |s| <= 0.1716.
    const vfloat<N> s = (m - 1.f) / (m + 1.f);
    const vfloat<N> s2 = s * s;
    vfloat<N> p = splat<N>(1.f / 9.f);
    p = p * s2 + 1.f / 7.f;
    p = p * s2 + 1.f / 5.f;
    p = p * s2 + 1.f / 3.f;
    p = p * s2 + 1.f;
    return __builtin_convertvector(e, vfloat<N>) + p * s * 2.88539008178f;
}

// The depth edge-stopping term |z - zq| / (sigmaZ |grad . offset| + relEps |z|)
// of SVGF (offset in pixels; the vector form of detail::depthTerm): 0 where
// the depths are equal, +inf where the denominator is not positive.
template <int N>
RTLAB_SIMD_INLINE vfloat<N> depthTerm(const vfloat<N>& z, const vfloat<N>& zq, const vfloat<N>& gradX,
                                      const vfloat<N>& gradY, const vfloat<N>& offX, const vfloat<N>& offY,
                                      float sigmaZ, float relEps) {
    const vfloat<N> dz = abs<N>(z - zq);
    const vfloat<N> den = abs<N>(gradX * offX + gradY * offY) * sigmaZ + abs<N>(z) * relEps;
    return select<N>(dz == 0.f, splat<N>(0.f), select<N>(den > 0.f, dz / den, splat<N>(HUGE_VALF)));
}

// n . n' of two normals stored as x, y, z planes, at indices i and j.
template <int N>
RTLAB_SIMD_INLINE vfloat<N> normalDot(const float* nx, const float* ny, const float* nz, std::size_t i, std::size_t j) {
    return loadu<N>(nx + i) * loadu<N>(nx + j) + loadu<N>(ny + i) * loadu<N>(ny + j) +
           loadu<N>(nz + i) * loadu<N>(nz + j);
}

// max(0, d)^sigmaN for d = n.n' (clamped to [0, 1], NaN -> 0): repeated
// squaring for integer exponents up to 4096 (the paper's 128 = 2^7 takes 7
// squarings), exp2/log2 otherwise.
struct NormalPower {
    float sigma;
    unsigned integer;
    bool isInteger;
    int squarings = -1;  // sigma = 2^squarings, else -1
    explicit NormalPower(float sigmaN)
        : sigma(sigmaN > 0.f ? sigmaN : 0.f),
          integer(sigma <= 4096.f && std::floor(sigma) == sigma ? static_cast<unsigned>(sigma) : 0u),
          isInteger(sigma <= 4096.f && std::floor(sigma) == sigma) {
        if (isInteger && integer != 0u && (integer & (integer - 1u)) == 0u)
            for (squarings = 0; (1u << squarings) != integer; ++squarings) {}
    }
    template <int N>
    RTLAB_SIMD_INLINE vfloat<N> apply(vfloat<N> d) const {
        d = min<N>(positiveOrZero<N>(d), splat<N>(1.f));
        if (sigma == 0.f) return splat<N>(1.f);
        if (squarings >= 0) {
            for (int k = 0; k < squarings; ++k) d *= d;
            return d;
        }
        if (isInteger) {
            vfloat<N> r = splat<N>(1.f), b = d;
            for (unsigned e = integer; e != 0u; e >>= 1u) {
                if (e & 1u) r *= b;
                b *= b;
            }
            return r;
        }
        const vfloat<N> safe = select<N>(d > 0.f, d, splat<N>(1.f));
        const vfloat<N> p = exp2NonPositive<N>(log2Positive<N>(safe) * sigma);
        return select<N>(d > 0.f, select<N>(d < 1.f, p, splat<N>(1.f)), splat<N>(0.f));
    }
};

}  // namespace rtlab::denoise::simd
