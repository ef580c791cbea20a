#pragma once
// Deterministic parallelism: work is split into fixed tiles whose layout does
// not depend on the thread count; per-tile results are reduced in tile order.
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <functional>
#include <memory>
#include <vector>

namespace rtlab {

struct Tile {
    int x0 = 0, y0 = 0, x1 = 0, y1 = 0;  // half-open pixel rectangle
    int index = 0;                       // position in row-major tile order
};

// Row-major tiles of tileSize x tileSize (edge tiles are smaller).
inline std::vector<Tile> makeTiles(int width, int height, int tileSize = 16) {
    std::vector<Tile> tiles;
    for (int y = 0; y < height; y += tileSize)
        for (int x = 0; x < width; x += tileSize)
            tiles.push_back(
                {x, y, std::min(x + tileSize, width), std::min(y + tileSize, height), static_cast<int>(tiles.size())});
    return tiles;
}

// The pixels (y * width + x) in tile order: makeTiles' tiles in order, each
// row-major. Thread k of a pipeline dispatch is pixel tilePixelOrder(...)[k]
// (tracer::Pipeline numbers a dispatch's threads this way).
inline std::vector<std::uint32_t> tilePixelOrder(int width, int height, int tileSize = 16) {
    std::vector<std::uint32_t> pixels;
    pixels.reserve(std::size_t(std::max(width, 0)) * std::size_t(std::max(height, 0)));
    for (const Tile& t : makeTiles(width, height, tileSize))
        for (int y = t.y0; y < t.y1; ++y)
            for (int x = t.x0; x < t.x1; ++x) pixels.push_back(static_cast<std::uint32_t>(y * width + x));
    return pixels;
}

// Runs body(i) for i in [0, count), in parallel, one task per index.
template <class Body>
void parallelForEach(std::size_t count, Body&& body) {
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, count, 1),
        [&](const tbb::blocked_range<std::size_t>& r) {
            for (std::size_t i = r.begin(); i != r.end(); ++i) body(i);
        },
        tbb::simple_partitioner{});
}

// The same, each index preferably on the host thread that ran it in the
// last call with the same `affinity` (its data stays in that thread's cache).
template <class Body>
void parallelForEach(std::size_t count, Body&& body, tbb::affinity_partitioner& affinity) {
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, count, 1),
        [&](const tbb::blocked_range<std::size_t>& r) {
            for (std::size_t i = r.begin(); i != r.end(); ++i) body(i);
        },
        affinity);
}

// Runs every task, in parallel; then rethrows the error of the first task
// (in the tasks' order) that failed, so the error reported does not depend
// on timing.
inline void runAllInParallel(const std::vector<std::function<void()>>& tasks) {
    std::vector<std::exception_ptr> errors(tasks.size());
    parallelForEach(tasks.size(), [&](std::size_t i) {
        try {
            tasks[i]();
        } catch (...) {
            errors[i] = std::current_exception();
        }
    });
    for (const std::exception_ptr& e : errors)
        if (e) std::rethrow_exception(e);
}

// Runs body(begin, end) over [0, count) in fixed chunks of `chunk` indices,
// in parallel. The chunks do not depend on the thread count, so per-chunk
// partial results reduced in chunk order are deterministic.
template <class Body>
void parallelForChunks(std::size_t count, std::size_t chunk, Body&& body) {
    if (count == 0) return;
    chunk = std::max<std::size_t>(chunk, 1);
    const std::size_t chunks = (count + chunk - 1) / chunk;
    parallelForEach(chunks, [&](std::size_t c) { body(c * chunk, std::min(count, (c + 1) * chunk)); });
}

// The chunk size of per-pixel loops over image planes (parallelForChunks):
// large enough that a task's overhead is noise, small enough to spread a
// 320x180 image over a few cores.
inline constexpr std::size_t kPixelChunk = 4096;

namespace parallel_internal {
inline constexpr std::size_t kPageBytes = 4096;
// One byte written per 4 KiB page of [room + first pages, room + end pages).
// Not checked by AddressSanitizer: its container annotations (libc++, or
// libstdc++ with _GLIBCXX_SANITIZE_VECTOR) mark a vector's room beyond
// size() as unaddressable, while it is allocated storage without objects,
// which may be written.
__attribute__((no_sanitize_address)) inline void touchPages(unsigned char* room, std::size_t first, std::size_t end) {
    for (std::size_t page = first; page < end; ++page) room[page * kPageBytes] = 0;
}
}  // namespace parallel_internal

// Room for `count` elements in `v`, the pages of the room beyond v.size()
// first written in parallel (one byte per page). First writes of new memory
// fault in pages one at a time, and on a VM that costs seconds per GB on
// one thread: a buffer constructed afterwards (assign, resize, push_back)
// then writes to memory already mapped. The elements are unchanged.
template <class T>
void reserveTouchedInParallel(std::vector<T>& v, std::size_t count) {
    if (count <= v.size()) return;
    v.reserve(count);
    // Step: the bytes past the elements are storage without objects; writing
    // them is allowed, and the later construction overwrites them.
    unsigned char* room = reinterpret_cast<unsigned char*>(v.data() + v.size());
    const std::size_t bytes = (count - v.size()) * sizeof(T);
    constexpr std::size_t kPagesPerTask = 1024;
    const std::size_t pages = (bytes + parallel_internal::kPageBytes - 1) / parallel_internal::kPageBytes;
    parallelForChunks(pages, kPagesPerTask,
                      [&](std::size_t begin, std::size_t end) { parallel_internal::touchPages(room, begin, end); });
}

// `count` copies of `value`, the memory first written in parallel
// (reserveTouchedInParallel): a frame-sized buffer without a second of page
// faults on one thread.
template <class T>
std::vector<T> vectorTouchedInParallel(std::size_t count, const T& value = T{}) {
    std::vector<T> v;
    reserveTouchedInParallel(v, count);
    v.assign(count, value);
    return v;
}

// How many threads parallel work may use now: the ThreadLimit in force, or
// all cores.
inline int threadCount() {
    return static_cast<int>(tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
}

// Limits TBB to `threads` worker threads for the lifetime of this object
// (0 = TBB's default: all cores).
class ThreadLimit {
public:
    explicit ThreadLimit(int threads) {
        if (threads > 0)
            control_ = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                             static_cast<std::size_t>(threads));
    }

private:
    std::unique_ptr<tbb::global_control> control_;
};

}  // namespace rtlab
