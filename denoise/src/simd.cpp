#include "simd.hpp"

#include <atomic>

namespace rtlab::denoise::simd {
namespace {
std::atomic<int> forcedWidth{0};
}

int preferredWidth() {
    const int forced = forcedWidth.load(std::memory_order_relaxed);
    if (forced == 4 || forced == 8) return forced;
    return hasAvx2() ? 8 : 4;
}

void overrideWidth(int width) {
    // 8 only where the CPU runs AVX2 (anything else would be an illegal instruction).
    const bool valid = width == 4 || (width == 8 && hasAvx2());
    forcedWidth.store(valid ? width : 0, std::memory_order_relaxed);
}

}  // namespace rtlab::denoise::simd
