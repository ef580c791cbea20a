#include <rtlab/core/simd.hpp>

namespace rtlab::simd {

bool hasAvx2() {
    static const bool avx2 = __builtin_cpu_supports("avx2");
    return avx2;
}

}  // namespace rtlab::simd
