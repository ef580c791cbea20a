// RingQueue: FIFO order across wrap-around and growth, against std::deque.
#include <rtlab/core/ring_queue.hpp>

#include <gtest/gtest.h>

#include <cstdint>
#include <deque>
#include <random>

TEST(RingQueue, KeepsFifoOrderThroughWrapAroundAndGrowth) {
    rtlab::RingQueue<std::uint64_t> ring;
    std::deque<std::uint64_t> reference;
    std::mt19937 rng(5);
    std::uint64_t next = 0;
    for (int step = 0; step < 20000; ++step) {
        // Mostly pushes early, mostly pops later: the ring grows, wraps and drains.
        const bool push = reference.empty() || (rng() % 100) < (step < 10000 ? 60u : 40u);
        if (push) {
            ring.push_back(next);
            reference.push_back(next++);
        } else {
            ASSERT_EQ(ring.front(), reference.front()) << step;
            ring.pop_front();
            reference.pop_front();
        }
        ASSERT_EQ(ring.size(), reference.size()) << step;
        ASSERT_EQ(ring.empty(), reference.empty()) << step;
    }
    ring.clear();
    EXPECT_TRUE(ring.empty());
    ring.push_back(7);
    EXPECT_EQ(ring.front(), 7u);
}
