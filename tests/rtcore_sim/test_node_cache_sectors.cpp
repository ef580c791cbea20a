// Sectored node-cache lines (cache.sectorBytes, docs/rtcore-model.md "Node
// cache and memory"): a line is allocated whole, its sectors are looked up,
// read and counted one by one; with sectorBytes = 0 a line is one sector.
#include <gtest/gtest.h>

#include <rtlab/core/error.hpp>
#include <rtlab/rtcore_sim/cache.hpp>
#include <rtlab/rtcore_sim/config.hpp>

using namespace rtlab::rtcore_sim;

namespace {

CacheParams sectored(std::uint32_t sectorBytes) {
    CacheParams p;
    p.sizeBytes = 2 * 128;  // one set of two 128-byte lines
    p.lineBytes = 128;
    p.ways = 2;
    p.hitLatency = 4;
    p.sectorBytes = sectorBytes;
    return p;
}

MemoryParams memory() {
    MemoryParams m;
    m.latency = 100;
    m.bytesPerCycle = 32;
    return m;
}

}  // namespace

TEST(NodeCacheSectors, SectorsOfAPresentLineAreReadOneByOne) {
    NodeCache cache(sectored(32));
    MemoryPort port(memory(), nullptr, 0);
    // A 40-byte fetch at 0 touches sectors 0 and 1: two sector misses, 64 bytes read.
    cache.fetch(MemoryRange{0, 40}, 0, port);
    EXPECT_EQ(cache.accesses, 2u);
    EXPECT_EQ(cache.misses, 2u);
    EXPECT_EQ(port.channel.readBytes, 64u);
    // Sector 3 of the same line: the line is there, the sector is not (a sector miss, 32 more bytes).
    cache.fetch(MemoryRange{96, 32}, 1000, port);
    EXPECT_EQ(cache.misses, 3u);
    EXPECT_EQ(cache.evictions, 0u);
    EXPECT_EQ(port.channel.readBytes, 96u);
    // Sectors 0, 1 and 3 again: hits, ready hitLatency later.
    const LineFill again = cache.fetch(MemoryRange{0, 128}, 2000, port);
    EXPECT_EQ(cache.hits, 3u);
    EXPECT_EQ(cache.misses, 4u);  // sector 2 was never read
    EXPECT_EQ(port.channel.readBytes, 128u);
    EXPECT_GT(again.ready, 2000u + 4u);  // it waits for sector 2
}

TEST(NodeCacheSectors, AllocationEvictsTheWholeLine) {
    NodeCache cache(sectored(32));
    MemoryPort port(memory(), nullptr, 0);
    cache.fetch(MemoryRange{0, 128}, 0, port);      // line 0, all four sectors
    cache.fetch(MemoryRange{128, 32}, 1000, port);  // line 1, one sector (the set's second way)
    cache.fetch(MemoryRange{256, 32}, 2000, port);  // line 2 evicts line 0 (LRU) with its four sectors
    EXPECT_EQ(cache.evictions, 1u);
    const std::uint64_t missesBefore = cache.misses;
    cache.fetch(MemoryRange{64, 32}, 3000, port);  // a sector of line 0 again: a miss
    EXPECT_EQ(cache.misses, missesBefore + 1);
}

TEST(NodeCacheSectors, UnsectoredLinesAreOneSector) {
    NodeCache cache(sectored(0));
    MemoryPort port(memory(), nullptr, 0);
    cache.fetch(MemoryRange{0, 40}, 0, port);
    cache.fetch(MemoryRange{96, 32}, 1000, port);
    EXPECT_EQ(cache.accesses, 2u);
    EXPECT_EQ(cache.misses, 1u);
    EXPECT_EQ(port.channel.readBytes, 128u);
}

TEST(NodeCacheSectors, ConfigurationRules) {
    RtCoreConfig config;
    config.cache.lineBytes = 128;
    config.cache.sizeBytes = 128 * 4 * 8;
    config.cache.sectorBytes = 128;  // not smaller than the line
    EXPECT_THROW(config.validate("test"), rtlab::InputError);
    config.cache.sectorBytes = 32;
    EXPECT_NO_THROW(config.validate("test"));
    config.l2.mode = L2Mode::Cache;
    config.l2.lineBytes = 32;  // the L2 line holds one sector: allowed
    config.l2.sizeBytes = 32 * 16 * 16 * 64;
    EXPECT_NO_THROW(config.validate("test"));
    config.cache.sectorBytes = 64;  // a fill unit larger than the L2 line
    EXPECT_THROW(config.validate("test"), rtlab::InputError);
}
