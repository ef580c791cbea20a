// Deterministic parallel helpers (core/parallel.hpp): the pixel order of a
// dispatch's threads, and which error a set of parallel tasks reports.
#include <rtlab/core/parallel.hpp>

#include <gtest/gtest.h>

#include <atomic>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

using namespace rtlab;

// A 20x18 image: tiles (0,0) 16x16, (16,0) 4x16, (0,16) 16x2, (16,16) 4x2.
TEST(Parallel, TilePixelOrderGoesTileByTileRowMajorInside) {
    const std::vector<std::uint32_t> order = tilePixelOrder(20, 18);
    ASSERT_EQ(order.size(), 20u * 18u);
    EXPECT_EQ(order[0], 0u);
    EXPECT_EQ(order[15], 15u);
    EXPECT_EQ(order[16], 20u);                // the first tile's second row
    EXPECT_EQ(order[256], 16u);               // the second tile starts at x = 16
    EXPECT_EQ(order[256 + 4], 36u);           // its second row
    EXPECT_EQ(order[256 + 64], 16u * 20u);    // the third tile starts at y = 16
    EXPECT_EQ(order.back(), 20u * 18u - 1u);  // the last tile's last pixel
}

// Every task runs; the error reported is the first failed task's in the
// tasks' order, whichever failed first in time.
TEST(Parallel, RunAllInParallelRethrowsTheFirstFailureInOrder) {
    const ThreadLimit limit(2);
    for (int repeat = 0; repeat < 20; ++repeat) {
        std::atomic<int> ran{0};
        std::vector<std::function<void()>> tasks;
        tasks.emplace_back([&] { ++ran; });
        tasks.emplace_back([&] {
            ++ran;
            throw std::runtime_error("second");
        });
        tasks.emplace_back([&] {
            ++ran;
            throw std::runtime_error("third");
        });
        tasks.emplace_back([&] { ++ran; });
        try {
            runAllInParallel(tasks);
            FAIL() << "no error";
        } catch (const std::runtime_error& e) {
            EXPECT_EQ(std::string(e.what()), "second");
        }
        EXPECT_EQ(ran.load(), 4);
    }
    runAllInParallel({});  // nothing to do
}
