#include <rtlab/rtcore_sim/config.hpp>
#include <gtest/gtest.h>
TEST(RtCoreConfig, Placeholder) { EXPECT_EQ(rtlab::rtcore_sim::RtCoreConfig{}.bvh.width, 6u); }
