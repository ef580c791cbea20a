#include "simd.hpp"

#include <atomic>

namespace rtlab::denoise::simd {
namespace {
std::atomic<int> forcedWidth{0};
}

int preferredWidth() {
    const int forced = forcedWidth.load(std::memory_order_relaxed);
    if (forced == 4 || forced == 8) return forced;
    static const bool avx2 = __builtin_cpu_supports("avx2");
    return avx2 ? 8 : 4;
}

void overrideWidth(int width) { forcedWidth.store(width == 4 || width == 8 ? width : 0, std::memory_order_relaxed); }

}  // namespace rtlab::denoise::simd
