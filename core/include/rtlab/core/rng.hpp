#pragma once
// Stateless random numbers: every sample is a pure function of
// (pixel, frame, sample, bounce, seed, dimension). No shared generator, so
// results do not depend on thread count or scheduling order.
#include <cstdint>

namespace rtlab {

// PCG-RXS-M-XS 32-bit hash (Jarzynski & Olano 2020, "Hash Functions for GPU Rendering").
constexpr std::uint32_t pcgHash(std::uint32_t v) {
    const std::uint32_t state = v * 747796405u + 2891336453u;
    const std::uint32_t word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

struct SampleKey {
    std::uint32_t pixel = 0;   // linear pixel index y * width + x
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

}  // namespace rtlab
