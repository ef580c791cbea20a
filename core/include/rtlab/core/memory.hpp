#pragma once
// Process-wide allocation policy for the programs (rtlab, benchmarks).
#include <malloc.h>

namespace rtlab {

// Keeps freed memory in the heap instead of returning it to the kernel
// (glibc): every frame allocates and frees image-sized buffers (tens of MB),
// and with the defaults each is a fresh mmap whose first touch page-faults
// (measured on the 2-core development VM: 2.6 ms per MB; `rtlab render
// --scene builtin:showcase --width 480 --height 270 --effects ao --threads 1`
// denoised a frame in 88 ms before, 70 ms after). Call once at the start of main.
inline void retainFreedMemory() {
    mallopt(M_MMAP_THRESHOLD, 1 << 30);
    mallopt(M_TRIM_THRESHOLD, 1 << 30);
}

}  // namespace rtlab
