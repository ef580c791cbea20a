#pragma once
// Stateless random numbers: every sample is a pure function of
// (pixel, frame, sample, bounce, seed, dimension). No shared generator, so
// results do not depend on thread count or scheduling order.
#include <rtlab/core/math.hpp>

#include <cstdint>

namespace rtlab {

// PCG-RXS-M-XS 32-bit hash (Jarzynski & Olano 2020, "Hash Functions for GPU Rendering").
constexpr std::uint32_t pcgHash(std::uint32_t v) {
    const std::uint32_t state = v * 747796405u + 2891336453u;
    const std::uint32_t word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

struct SampleKey {
    std::uint32_t pixel = 0;  // linear pixel index y * width + x
    std::uint32_t frame = 0;
    std::uint32_t sample = 0;  // sample index within the pixel
    std::uint32_t bounce = 0;
    std::uint32_t seed = 0;
};

// Hash of the key and a dimension index (which random number of this sample).
constexpr std::uint32_t sampleHash(const SampleKey& k, std::uint32_t dimension) {
    std::uint32_t h = pcgHash(k.seed ^ 0x9e3779b9u);
    h = pcgHash(h ^ k.pixel);
    h = pcgHash(h ^ k.frame);
    h = pcgHash(h ^ k.sample);
    h = pcgHash(h ^ k.bounce);
    return pcgHash(h ^ dimension);
}

// Uniform float in [0, 1): 24 high bits, so 1.0 is never returned.
constexpr float sampleUniform(const SampleKey& k, std::uint32_t dimension) {
    return static_cast<float>(sampleHash(k, dimension) >> 8) * (1.0f / 16777216.0f);
}

// ------------------------------------------ screen-space stratified 2D --
//
// A 2D sample whose errors are spread over the screen as blue noise: the
// pixels are ordered along a Morton (Z) curve, pixel m's samples are the
// points m * samplesPerPixel + sample of a (0, 2)-sequence in base 2 (Sobol'
// dimensions 1 and 2), and the whole point set is Owen-scrambled by a hash
// of the key's (frame, bounce, seed) and the dimension pair (Ahmed & Wonka
// 2020, "Screen-Space Blue-Noise Diffusion of Monte Carlo Sampling Error
// via Hierarchical Ordering of Pixels"; the hash-based Owen scramble of
// Burley 2020, "Practical Hash-based Owen Scrambling"). With samplesPerPixel
// a power of two, 2^s, every aligned block of 2^(2k) pixels holds a
// (0, 2k + s, 2)-net of its 2^(2k + s) points, so a spatial filter
// averages stratified samples, and each pixel's own samples are a (0, s,
// 2)-net. Each point is uniform in [0, 1)^2 over the scramble, so estimates
// stay unbiased; the pixel's samples depend on samplesPerPixel. Stateless: a pure function of (x, y,
// sample, samplesPerPixel, frame, bounce, seed, dimension); the key's pixel
// and sample fields are not used (x, y and `sample` say them).

// Bits of v in reverse order.
constexpr std::uint32_t reverseBits(std::uint32_t v) {
    v = ((v >> 1) & 0x55555555u) | ((v & 0x55555555u) << 1);
    v = ((v >> 2) & 0x33333333u) | ((v & 0x33333333u) << 2);
    v = ((v >> 4) & 0x0F0F0F0Fu) | ((v & 0x0F0F0F0Fu) << 4);
    v = ((v >> 8) & 0x00FF00FFu) | ((v & 0x00FF00FFu) << 8);
    return (v >> 16) | (v << 16);
}

// A nested uniform (Owen) scramble of v's bits: bit d is flipped by a hash
// of the bits above it and the seed (Burley 2020, section 3: the
// Laine-Karras permutation on the reversed bits; its constants).
constexpr std::uint32_t owenScramble(std::uint32_t v, std::uint32_t seed) {
    v = reverseBits(v);
    v += seed;
    v ^= v * 0x6c50b47cu;
    v ^= v * 0xb82f1e52u;
    v ^= v * 0xc7afe638u;
    v ^= v * 0x8d22f6e6u;
    return reverseBits(v);
}

// The first 16 bits of x and y interleaved (x in the even bits).
constexpr std::uint32_t mortonIndex(std::uint32_t x, std::uint32_t y) {
    const auto spread = [](std::uint32_t v) {
        v &= 0xFFFFu;
        v = (v | (v << 8)) & 0x00FF00FFu;
        v = (v | (v << 4)) & 0x0F0F0F0Fu;
        v = (v | (v << 2)) & 0x33333333u;
        return (v | (v << 1)) & 0x55555555u;
    };
    return spread(x) | (spread(y) << 1);
}

// Sobol' dimensions 1 and 2 of point `index` as 32-bit fractions: the
// first is the van der Corput radical inverse, the second the Pascal
// matrix mod 2 (direction numbers v_k: v_0 = 2^31, v_(k+1) = v_k ^ v_k >> 1).
// The second is a table lookup per byte of the index (each byte's 256
// combinations of its 8 direction numbers, XOR-ed), not a loop per bit.
struct SobolSecondDimensionTable {
    std::uint32_t bytes[4][256] = {};
    constexpr SobolSecondDimensionTable() {
        std::uint32_t direction[32] = {};
        std::uint32_t v = 0x80000000u;
        for (int k = 0; k < 32; ++k, v ^= v >> 1) direction[k] = v;
        for (int b = 0; b < 4; ++b)
            for (std::uint32_t byte = 0; byte < 256; ++byte) {
                std::uint32_t x = 0;
                for (int k = 0; k < 8; ++k)
                    if (byte & (1u << k)) x ^= direction[8 * b + k];
                bytes[b][byte] = x;
            }
    }
};
inline constexpr SobolSecondDimensionTable kSobolSecondDimension{};

constexpr void sobol2(std::uint32_t index, std::uint32_t& first, std::uint32_t& second) {
    first = reverseBits(index);
    const auto& t = kSobolSecondDimension.bytes;
    second = t[0][index & 0xFFu] ^ t[1][(index >> 8) & 0xFFu] ^ t[2][(index >> 16) & 0xFFu] ^ t[3][index >> 24];
}

// Two uniform floats in [0, 1) (24 bits each) for sample `sample` of pixel
// (x, y) with samplesPerPixel samples a pixel; `dimension` picks the
// scramble (distinct values for unrelated 2D decisions of one sample).
// Pixels beyond 65535 in x or y wrap in the Morton order (still uniform,
// less stratified); `sample` should be below samplesPerPixel.
inline vec2 sampleScreenStratified2D(std::uint32_t x, std::uint32_t y, std::uint32_t sample,
                                     std::uint32_t samplesPerPixel, const SampleKey& k, std::uint32_t dimension) {
    SampleKey scrambleKey = k;
    scrambleKey.pixel = 0xFFFFFFFFu;  // one scramble for the whole frame
    scrambleKey.sample = 0;
    const std::uint32_t spp = samplesPerPixel > 0 ? samplesPerPixel : 1;
    // Step: the point's index in 64 bits; above 2^32 (say 1080p at more than
    // 1024 spp) the high bits pick another scramble, not the same points
    // again. The index's order within aligned blocks is shuffled (an Owen
    // scramble of the index keeps every aligned block of points whole).
    const std::uint64_t index64 = std::uint64_t{mortonIndex(x, y)} * spp + sample;
    std::uint32_t seed = sampleHash(scrambleKey, dimension);
    if (const std::uint32_t high = static_cast<std::uint32_t>(index64 >> 32)) seed = pcgHash(seed ^ pcgHash(high));
    const std::uint32_t index = owenScramble(static_cast<std::uint32_t>(index64), seed);
    std::uint32_t a = 0, b = 0;
    sobol2(index, a, b);
    // Step: each coordinate scrambled on its own seed.
    a = owenScramble(a, pcgHash(seed ^ 0x68bc21ebu));
    b = owenScramble(b, pcgHash(seed ^ 0x02e5be93u));
    return vec2(static_cast<float>(a >> 8) * (1.0f / 16777216.0f), static_cast<float>(b >> 8) * (1.0f / 16777216.0f));
}

}  // namespace rtlab
