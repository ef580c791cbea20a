// Deterministic parallel helpers (core/parallel.hpp): the pixel order of a
// dispatch's threads, which error a set of parallel tasks reports, and
// buffers whose pages are first written in parallel.
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

// Room touched in parallel: the elements already there are kept, the room
// holds `count`, and a later assign sees no trace of the touching.
TEST(Parallel, ReserveTouchedInParallelKeepsTheElementsAndMakesRoom) {
    const ThreadLimit limit(2);
    std::vector<std::uint64_t> v{7, 8, 9};
    reserveTouchedInParallel(v, 3'000'000);  // ~23 MB: several tasks of 1024 pages
    EXPECT_EQ(v, (std::vector<std::uint64_t>{7, 8, 9}));
    EXPECT_GE(v.capacity(), 3'000'000u);
    const std::uint64_t* room = v.data();
    v.resize(3'000'000, 5);
    EXPECT_EQ(v.data(), room);  // no reallocation: the room was there
    EXPECT_EQ(v[2], 9u);
    EXPECT_EQ(v[3], 5u);
    EXPECT_EQ(v.back(), 5u);
    reserveTouchedInParallel(v, 10);  // smaller than the size: nothing changes
    EXPECT_EQ(v.size(), 3'000'000u);
    EXPECT_EQ(v.data(), room);
}

TEST(Parallel, VectorTouchedInParallelHoldsCopiesOfTheValue) {
    struct Defaulted {
        float x = 1.5f;
        int y = -3;
    };
    const std::vector<Defaulted> d = vectorTouchedInParallel<Defaulted>(100'000);
    ASSERT_EQ(d.size(), 100'000u);
    EXPECT_EQ(d.front().x, 1.5f);
    EXPECT_EQ(d.back().y, -3);
    const std::vector<int> v = vectorTouchedInParallel(5000, 42);
    EXPECT_EQ(v, std::vector<int>(5000, 42));
    EXPECT_TRUE(vectorTouchedInParallel<int>(0).empty());
}
