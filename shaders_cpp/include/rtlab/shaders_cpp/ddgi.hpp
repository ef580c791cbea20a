#pragma once
// DDGI probe volume (Majercik et al. 2019, "Dynamic Diffuse Global
// Illumination with Ray-Traced Irradiance Fields", JCGT 8(2)) as a plain data
// module: it chooses the probe grid and the per-frame ray directions, blends
// ray results that the *caller* traced into octahedral irradiance and
// distance-moment tiles, and answers visibility-weighted irradiance queries.
// It never traces rays itself and depends on nothing but core and the
// sampling toolkit (sampling.hpp).
//
// Conventions
//   * Units. Positions, biases and distances are world units. Ray radiance is
//     radiance L (W sr^-1 m^-2, or whatever unit the caller's radiance has).
//   * Stored irradiance. An irradiance texel in direction n holds the
//     irradiance E(n) = integral over the hemisphere around n of L cos, i.e.
//     pi times the cosine-weighted mean radiance (a uniform environment L
//     gives E = pi L). irradiance() returns E, so the caller's outgoing
//     diffuse radiance is albedo / pi * E. With irradianceGamma != 1 the
//     texels hold E^(1/gamma) (see DdgiSettings::irradianceGamma).
//   * Distance texels hold the moments (mean distance, mean squared distance)
//     of the distances seen around their direction, in world units, each
//     clamped to maxRayDistance().
//   * Tiles follow sampling.hpp: N x N octahedral interior plus a one-texel
//     border, (N+2)^2 texels row-major per probe; the atlases store the tiles
//     of probe 0, 1, 2, ... back to back (probe-major).
//   * Probe order: grid coordinate (x, y, z) has index x + nx (y + ny z).
//   * Determinism: update() is parallel over probes; every texel is a pure
//     function of its probe's results, summed in ray order, so atlases are
//     bit-identical for any thread count.
#include <rtlab/core/math.hpp>

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

namespace rtlab::shaders {

struct DdgiSettings {
    // Probes per axis. 0 = automatic for that axis: the spacing target is
    // (largest extent of the inflated bounds) / (maxProbesPerAxis - 1), and an
    // axis gets ceil(extent / target) + 1 probes, clamped to
    // [2, maxProbesPerAxis] - so a 10 x 3 x 10 room gets 8 x 4 x 8 probes with
    // near-cubic cells. Explicit counts must lie in [2, 64].
    glm::ivec3 probeCounts{0};
    // Cap for automatic counts (at most 8^3 = 512 probes: 512 x 128 = 64k rays
    // per update, the ray budget of a 256 x 256 frame at 1 sample per pixel).
    int maxProbesPerAxis = 8;
    // Rays per probe and update, in [1, 65536]. 128 (the paper uses 64 to 256):
    // each irradiance texel's cosine lobe then covers ~64 rays, i.e. ~12%
    // single-frame noise before the hysteresis averages ~1 / (1 - 0.97) = 33
    // frames, at half the cost of 256 rays.
    std::uint32_t raysPerProbe = 128;
    // Interior texels per tile side (the paper's 8 and 16), in [1, 64]: 10x10
    // and 18x18 texels with the border. Irradiance is smooth (a cosine
    // convolution), distances are sharp, hence the finer distance tiles.
    int irradianceTexels = 8;
    int distanceTexels = 16;
    // Weight of the previous value when blending in a new frame, in [0, 1]
    // (paper: 0.97). 0 = no history.
    float hysteresis = 0.97f;
    // A probe whose latest rays hit back faces more often than this fraction
    // sits inside geometry: its results are not blended and it is left out of
    // irradiance() (unless all eight around a point are), see relocation.
    // In [0, 1].
    float backfaceFractionInactive = 0.25f;
    // Probe relocation (Majercik et al. 2021, "Scaling Probe-Based Real-Time
    // Dynamic Global Illumination for Production", JCGT 10(2), sec. 5; the
    // RTXGI SDK's relocation pass). After each update a traced probe's offset
    // from its grid point changes, from its own rays (origin = the offset
    // position they were traced from):
    //   * inside (back-face fraction above backfaceFractionInactive): it
    //     moves through the closest back face it saw, to minFrontDistance
    //     beyond it: offset += dir * (|t| + minFrontDistance). If that would
    //     leave the bound below, it stays where it is and is classified
    //     Inside (see DdgiProbeState).
    //   * too close (closest front-face hit t_f < minFrontDistance): it moves
    //     away from that hit, along the ray most opposite to it, by
    //     min(minFrontDistance - t_f, half that ray's free distance).
    //   * clear (every hit farther than 1.25 minFrontDistance): it moves back
    //     toward its grid point by min(closest hit - 1.25 minFrontDistance,
    //     |offset|) - never closer than 1.25 minFrontDistance to what it saw,
    //     so it does not re-enter the geometry it left (the 1.25 keeps the
    //     too-close and move-back rules from alternating).
    // The offset is bounded: offset / (relocationMaxOffset x spacing) has
    // length <= 1 (an ellipsoid inside the half-cell around the grid point,
    // so a probe never passes a neighbour). Moves that would leave it are
    // scaled back onto it (too close, move back) or refused (inside).
    bool relocation = true;
    // Semi-axes of the offset bound, fraction of the spacing per axis, in [0, 0.5].
    float relocationMaxOffset = 0.45f;
    // minFrontDistance as a fraction of the smallest spacing, in [0, 0.5]:
    // 0.2 s_min is about the total self-shadow bias (0.225 s_min), so a probe
    // sits at least as far from a surface as the biased query points do.
    float relocationMinFrontDistance = 0.2f;
    // Probe classification (Majercik et al. 2021 sec. 5; RTXGI's
    // classification pass): after an update a traced, not-inside probe stays
    // Active only if one of its rays hit a surface (front or back face)
    // inside its influence box: its grid point +- one spacing per axis (the
    // eight cells whose queries use it) grown by normalBias + viewBias (a
    // biased query point may move into those cells). Otherwise no surface it
    // can see uses it: it becomes Idle. Idle and Inside probes trace no rays
    // (probeTraced() is false, update() ignores their results) and are left
    // out of queries, until wakeProbes() marks them for a new look (the DDGI
    // pass does so around geometry that moved, deformed, appeared or
    // disappeared). Off: every probe is traced every update.
    bool classification = true;
    // Exponent of max(0, dot(texel, ray)) weighting distance samples (paper:
    // 50: the lobe's half-weight angle is ~9.5 degrees, so occluders stay sharp).
    // In [0, 1000].
    float depthSharpness = 50.f;
    // Surface biases of the query point, world units, >= 0. The query moves by
    // normalBias * n + viewBias * viewDir before the visibility test, so that a
    // surface does not shadow itself against the probes' recorded distances.
    // Defaults follow the paper's listing: a total self-shadow bias of
    // 0.3 * 0.75 * (minimum probe spacing), split 20% along n and 80% toward
    // the viewer: normalBias = 0.045 s_min, viewBias = 0.18 s_min.
    std::optional<float> normalBias;
    std::optional<float> viewBias;
    // Distance recorded for misses and upper clamp of every distance, world
    // units, > 0. Default 1.5 x the probe cell diagonal: a query point is at
    // most one cell diagonal (plus the bias) from each of its 8 probes, so an
    // open probe's recorded distance must exceed that or free space would look
    // occluded; 1.5x leaves margin, and a shorter clamp keeps the variance of
    // open directions small. It does not limit the caller's radiance rays.
    std::optional<float> maxRayDistance;
    // Perceptual encoding exponent in [1, 16]. 1 (default) = texels store
    // linear irradiance: the atlases are float, so the paper's gamma-5 encoding
    // (meant for 10-bit textures and to speed up convergence in dark regions)
    // is not needed, and linear storage keeps the hysteresis an exact
    // exponential average. With gamma g the texels hold E^(1/g), hysteresis
    // blends encoded values, and queries decode each probe's bilinear sample
    // (x^g) before weighting.
    float irradianceGamma = 1.f;
};

// One traced probe ray. update() takes them indexed [probe * raysPerProbe + ray].
//   distance >= 0, finite : front-face hit at that distance; radiance used.
//   distance infinite     : miss (+inf, also -inf): radiance (sky) used,
//                           distance recorded as maxRayDistance.
//   distance < 0, finite  : back-face hit at |distance| (the paper/RTXGI
//                           convention): radiance ignored for irradiance (a
//                           probe does not see the inside of geometry), |d|
//                           used for the distance moments (a caller may
//                           shorten it, as RTXGI does with 0.2 |t|, so that the
//                           probe's view is blocked there).
//   distance NaN, or radiance with a NaN/Inf component: the sample is rejected
//   (skipped entirely) and counted in DdgiUpdateStats::rejectedSamples.
//   Finite radiance is clamped per component to [0, kDdgiMaxRadiance].
struct DdgiRayResult {
    vec3 radiance{0.f};
    float distance = kInfinity;
};

// Numerical safety clamp, not a firefly clamp: 65536 rays x 1e30 x pi stays
// far below FLT_MAX, so sums and blends never overflow.
inline constexpr float kDdgiMaxRadiance = 1e30f;

// What a probe is after the latest update (see DdgiSettings::relocation and
// ::classification). Only Active probes take part in irradiance() queries.
enum class DdgiProbeState : std::uint8_t {
    Active,      // traced, blended, queried
    Relocating,  // new, woken, or just moved out of geometry: traced next update, not yet queried
    Inside,      // inside geometry and cannot move out within the bound: not traced, not queried
    Idle,        // no surface in its influence box: not traced, not queried
};

struct DdgiUpdateStats {
    // Per probe, after the update (they sum to the probe count).
    std::uint32_t activeProbes = 0;
    std::uint32_t relocatingProbes = 0;
    std::uint32_t insideProbes = 0;
    std::uint32_t idleProbes = 0;
    std::uint32_t tracedProbes = 0;  // whose results this update consumed
    std::uint32_t movedProbes = 0;   // whose offset changed in this update
    std::uint32_t offsetProbes = 0;  // with a non-zero offset after it
    // Per ray, over the traced probes.
    std::uint64_t rays = 0;  // results consumed
    std::uint64_t misses = 0;
    std::uint64_t backfaceHits = 0;
    std::uint64_t rejectedSamples = 0;  // non-finite radiance or NaN distance
    std::uint64_t clampedSamples = 0;   // radiance clamped (negative or > kDdgiMaxRadiance)
};

// Row-major RGB image of an atlas: probe p's tile occupies tile column
// p % (nx ny) and tile row p / (nx ny), i.e. each row holds one xy-slab of
// the grid and z grows downward.
struct DdgiAtlasImage {
    int width = 0;
    int height = 0;
    std::vector<vec3> texels;  // width * height, index y * width + x
};

class DdgiVolume {
public:
    // The volume covers sceneBounds inflated by 1% of its largest extent per
    // side (at least 1e-3 and 1e-4 x the largest |coordinate|, so that float
    // spacing never collapses); each axis is first grown to at least 10% of
    // the largest extent, so flat scenes get a slab. Empty or non-finite bounds
    // become the cube [-1, 1]^3 (a volume over nothing is harmless and keeps
    // every query finite); coordinates are clamped to +-1e12.
    // Throws std::invalid_argument for settings outside the documented ranges
    // (e.g. raysPerProbe = 0).
    explicit DdgiVolume(const Aabb& sceneBounds, const DdgiSettings& settings = {});

    const DdgiSettings& settings() const { return settings_; }
    const Aabb& bounds() const { return bounds_; }  // inflated; probes sit on its corners
    glm::ivec3 probeCounts() const { return counts_; }
    vec3 probeSpacing() const { return spacing_; }
    std::uint32_t probeCount() const { return probeCount_; }
    std::uint32_t raysPerProbe() const { return settings_.raysPerProbe; }
    float normalBias() const { return normalBias_; }  // resolved defaults
    float viewBias() const { return viewBias_; }
    float maxRayDistance() const { return maxRayDistance_; }

    // Where the probe is: its grid point plus its relocation offset. Rays are
    // traced from here and queries measure directions and distances from here.
    vec3 probePosition(std::uint32_t probe) const;
    vec3 probeGridPosition(std::uint32_t probe) const;
    vec3 probeOffset(std::uint32_t probe) const;
    DdgiProbeState probeState(std::uint32_t probe) const;
    // Whether the caller must trace the probe's rays for the next update
    // (Active or Relocating; every probe with classification off). update()
    // ignores the results of the others (any value may be passed there).
    bool probeTraced(std::uint32_t probe) const;
    std::uint32_t tracedProbeCount() const;
    // Idle and Inside probes whose influence box (see
    // DdgiSettings::classification) overlaps `region` become Relocating: they
    // are traced at the next update and start a fresh history. Returns how many.
    std::uint32_t wakeProbes(const Aabb& region);
    // The box of world space whose surfaces may use the probe.
    Aabb probeInfluenceBox(std::uint32_t probe) const;

    // The paper's per-frame random rotation: randomRotation of three
    // sampleUniform dimensions keyed by (frame, seed) with
    // pixel = kRotationKeyPixel, the same for every probe in the frame.
    static mat3 frameRotation(std::uint32_t frameIndex, std::uint32_t seed);
    static constexpr std::uint32_t kRotationKeyPixel = 0xFFFFFFFFu;  // no real pixel
    // sphericalFibonacci(ray, raysPerProbe, frameRotation(frame, seed)); unit.
    // `probe` does not change the direction (one rotation per frame); it is
    // part of the signature for callers that loop over (probe, ray).
    vec3 rayDirection(std::uint32_t probe, std::uint32_t ray, std::uint32_t frameIndex, std::uint32_t seed) const;

    // Blends one frame of results (size must be probeCount() * raysPerProbe(),
    // else std::invalid_argument; directions must be rayDirection(.., frameIndex,
    // seed)). Per texel: the new irradiance is pi * sum(w L) / sum(w) with
    // w = max(0, dot(texel, ray)) over non-back-face samples, the new moments
    // are sum(w' (d, d^2)) / sum(w') with w' = w^depthSharpness; the stored
    // value becomes hysteresis * old + (1 - hysteresis) * new, or new on the
    // probe's first blend after construction / reset() / wakeProbes() / moving
    // out of geometry. A texel with sum of weights 0 keeps its old value.
    // Borders are refilled with ddgiFillTileBorder. Only traced probes
    // (probeTraced() before the call) are read; a probe found inside geometry
    // is not blended. Then relocation and classification run per probe.
    void update(std::span<const DdgiRayResult> results, std::uint32_t frameIndex, std::uint32_t seed);
    // Forget the history: irradiance 0, moments (maxRayDistance, maxRayDistance^2),
    // offsets 0, every probe Relocating (traced at the next update).
    void reset();
    std::uint64_t updatesSinceReset() const { return updates_; }
    const DdgiUpdateStats& lastUpdateStats() const { return lastStats_; }
    // Whether the probe takes part in queries (state Active).
    bool probeActive(std::uint32_t probe) const { return probeState(probe) == DdgiProbeState::Active; }

    // Irradiance E (see the header comment) at a surface point with normal
    // `normal` seen from direction `viewDir` (unit vector from the point toward
    // the viewer; zero = no view bias): the paper's query over the 8 probes of
    // the cell containing the biased point (clamped to the grid), weighting each
    // by trilinear x (smooth back-face ((dot(dirToProbe, n) + 1) / 2)^2 + 0.2) x
    // (Chebyshev visibility from the moments at the biased point), with weights
    // below 0.2 crushed by w^3 / 0.2^2, normalised. Always finite: a zero or
    // non-finite normal is taken as +z, a non-finite position gives 0.
    vec3 irradiance(vec3 position, vec3 normal, vec3 viewDir) const;
    // One probe's bilinearly filtered tiles (decoded irradiance E; moments).
    vec3 probeIrradiance(std::uint32_t probe, vec3 direction) const;
    vec2 probeDistanceMoments(std::uint32_t probe, vec3 direction) const;

    // Raw atlases, probe-major tiles (see the header comment). Irradiance
    // texels are encoded when irradianceGamma != 1.
    const std::vector<vec3>& irradianceAtlas() const { return irradiance_; }
    const std::vector<vec2>& distanceAtlas() const { return distance_; }
    int irradianceTileSize() const { return settings_.irradianceTexels + 2; }
    int distanceTileSize() const { return settings_.distanceTexels + 2; }
    // 2D debug layouts (see DdgiAtlasImage): decoded irradiance E; moments as
    // (mean, mean^2, 0).
    DdgiAtlasImage irradianceAtlasImage() const;
    DdgiAtlasImage distanceAtlasImage() const;

    // Bytes held by the volume's buffers (atlases, texel directions, scratch).
    std::size_t bytesAllocated() const;

private:
    const vec3* irradianceTile(std::uint32_t probe) const;
    const vec2* distanceTile(std::uint32_t probe) const;
    vec3 decode(vec3 stored) const;

    DdgiSettings settings_;
    Aabb bounds_;
    glm::ivec3 counts_{2};
    vec3 spacing_{1.f};
    std::uint32_t probeCount_ = 0;
    float normalBias_ = 0.f, viewBias_ = 0.f, maxRayDistance_ = 1.f;

    std::vector<vec3> irradiance_;                               // probeCount * (Ni+2)^2
    std::vector<vec2> distance_;                                 // probeCount * (Nd+2)^2
    std::vector<vec3> irradianceTexelDirs_, distanceTexelDirs_;  // interior, row-major
    std::vector<vec3> rayDirs_;                                  // scratch: this frame's directions
    std::vector<float> irradianceWeights_, distanceWeights_;     // scratch: texel x ray weights
    std::vector<DdgiUpdateStats> probeStats_;                    // scratch: per-probe counters
    std::vector<DdgiProbeState> states_;                         // per probe
    std::vector<vec3> offsets_;                                  // per probe, relocation offset
    std::vector<std::uint8_t> fresh_;  // per probe: 1 = the next blend replaces instead of blending
    std::vector<std::uint8_t> moved_;  // scratch: offset changed in this update
    std::uint64_t updates_ = 0;
    DdgiUpdateStats lastStats_;
};

}  // namespace rtlab::shaders
