#pragma once
// SIMD float vectors templated on the width, as Embree's vfloat<N>; rtlab
// uses two widths: 4 (SSE2, the x86-64 baseline) and 8 (AVX2, picked at run
// time when the CPU has it). Built on GCC/Clang vector extensions, so every
// operation is lane-wise IEEE arithmetic: a lane's result does not depend on
// the width or on which lanes share a vector (the project compiles in ISO
// mode, where contraction into FMA is off, and AVX2 code does not enable
// FMA). The denoiser's kernels (denoise/src/simd.hpp) and the tracer's
// watertight triangle clusters are built on these.
#include <cstdint>

#define RTLAB_SIMD_INLINE inline __attribute__((always_inline))

// The 8-wide helpers are always inlined into AVX2-targeted kernels, so the
// calling convention GCC warns about (AVX vectors returned without AVX) never
// applies.
#pragma GCC diagnostic ignored "-Wpsabi"

namespace rtlab::simd {

template <int N>
struct Lanes {
    typedef float vf __attribute__((vector_size(N * sizeof(float))));
    typedef std::int32_t vi __attribute__((vector_size(N * sizeof(std::int32_t))));
    // Unaligned vectors: loads and stores through this type are float
    // accesses (type-based alias analysis applies), unlike memcpy, which the
    // compiler must assume may overwrite any pointer it holds.
    typedef float vfUnaligned __attribute__((vector_size(N * sizeof(float)), aligned(alignof(float))));
};
template <int N>
using vfloat = typename Lanes<N>::vf;
template <int N>
using vint = typename Lanes<N>::vi;

// The CPU runs AVX2 (cached CPUID query).
bool hasAvx2();

// Every lane v (a broadcast: -0 stays -0, unlike adding v to a zero vector).
template <int N>
RTLAB_SIMD_INLINE vfloat<N> splat(float v) {
    vfloat<N> r;
    for (int i = 0; i < N; ++i) r[i] = v;
    return r;
}
template <int N>
RTLAB_SIMD_INLINE vfloat<N> loadu(const float* p) {
    return *reinterpret_cast<const typename Lanes<N>::vfUnaligned*>(p);
}
template <int N>
RTLAB_SIMD_INLINE void storeu(float* p, const vfloat<N>& v) {
    *reinterpret_cast<typename Lanes<N>::vfUnaligned*>(p) = v;
}
template <int N>
RTLAB_SIMD_INLINE vfloat<N> select(const vint<N>& mask, const vfloat<N>& a, const vfloat<N>& b) {
    return mask ? a : b;
}

// Bit i set where lane i of a comparison mask is true (movmskps).
template <int N>
RTLAB_SIMD_INLINE std::uint32_t signMask(const vint<N>& mask) {
    if constexpr (N == 4) {
        return static_cast<std::uint32_t>(__builtin_ia32_movmskps((vfloat<4>)mask));
    } else {
        // No movmskps without AVX in this (untargeted) template: each lane's
        // bit, then an OR-reduction by shuffles (a few vector instructions
        // once inlined into an AVX2 kernel, instead of 8 lane extracts).
        static_assert(N == 8);
        const vint<8> bits = (mask < 0) & vint<8>{1, 2, 4, 8, 16, 32, 64, 128};
        vint<4> r = __builtin_shufflevector(bits, bits, 0, 1, 2, 3) | __builtin_shufflevector(bits, bits, 4, 5, 6, 7);
        r = r | __builtin_shufflevector(r, r, 2, 3, 0, 1);
        r = r | __builtin_shufflevector(r, r, 1, 0, 3, 2);
        return static_cast<std::uint32_t>(r[0]);
    }
}

}  // namespace rtlab::simd
