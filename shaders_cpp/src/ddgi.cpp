#include <rtlab/shaders_cpp/ddgi.hpp>

#include <rtlab/core/parallel.hpp>
#include <rtlab/core/rng.hpp>
#include <rtlab/shaders_cpp/sampling.hpp>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace rtlab::shaders {
namespace {

constexpr double kPiD = 3.14159265358979323846;
constexpr float kMaxCoordinate = 1e12f;        // bounds are clamped to +-this
constexpr float kMaxQueryCoordinate = 1e15f;   // query positions are clamped to +-this
constexpr float kMaxRayDistanceLimit = 1e18f;  // so that d^2 stays finite in float
constexpr int kMaxProbesPerAxis = 64;
constexpr int kMaxTexels = 64;
constexpr std::uint32_t kMaxRaysPerProbe = 65536;
// The paper's query constants.
constexpr float kBackfaceFloor = 0.2f;    // smooth back-face weight's additive floor
constexpr float kMinProbeWeight = 1e-6f;  // before the crush
constexpr float kCrushThreshold = 0.2f;   // weights below are crushed by w^3 / t^2

[[noreturn]] void reject(const std::string& what) { throw std::invalid_argument("DdgiSettings: " + what); }

bool inRange(float v, float lo, float hi) { return std::isfinite(v) && v >= lo && v <= hi; }

// Divides v by its largest |component| so squares neither overflow nor
// underflow; false for zero or non-finite v.
bool prescale(vec3& v) {
    const float m = std::fmax(std::fabs(v.x), std::fmax(std::fabs(v.y), std::fabs(v.z)));
    if (!(m > 0.f) || !std::isfinite(m)) return false;
    v /= m;
    return true;
}

vec3 normalizeOr(vec3 v, vec3 fallback) {
    if (!prescale(v)) return fallback;
    return v / std::sqrt(glm::dot(v, v));
}

float maxComponent(vec3 v) { return std::max(v.x, std::max(v.y, v.z)); }
float minComponent(vec3 v) { return std::min(v.x, std::min(v.y, v.z)); }

vec3 clampVec(vec3 v, float limit) {
    // NaN-safe: fmin/fmax return the non-NaN operand.
    return {std::fmin(std::fmax(v.x, -limit), limit), std::fmin(std::fmax(v.y, -limit), limit),
            std::fmin(std::fmax(v.z, -limit), limit)};
}

Aabb resolveBounds(const Aabb& scene) {
    vec3 lo = scene.lo, hi = scene.hi;
    if (scene.empty() || !isFinite(lo) || !isFinite(hi)) lo = vec3(-1.f), hi = vec3(1.f);
    lo = clampVec(lo, kMaxCoordinate);
    hi = clampVec(hi, kMaxCoordinate);
    const float largest = maxComponent(hi - lo);
    // Flat axes grow symmetrically to 10% of the largest extent.
    for (int a = 0; a < 3; ++a) {
        if (hi[a] - lo[a] < 0.1f * largest) {
            const float c = 0.5f * (lo[a] + hi[a]);
            lo[a] = c - 0.05f * largest;
            hi[a] = c + 0.05f * largest;
        }
    }
    const float magnitude = maxComponent(glm::max(glm::abs(lo), glm::abs(hi)));
    const float pad = std::max({0.01f * largest, 1e-3f, 1e-4f * magnitude});
    Aabb out;
    out.lo = lo - vec3(pad);
    out.hi = hi + vec3(pad);
    return out;
}

void validate(const DdgiSettings& s) {
    for (int a = 0; a < 3; ++a) {
        const int c = s.probeCounts[a];
        if (c != 0 && (c < 2 || c > kMaxProbesPerAxis))
            reject("probeCounts[" + std::to_string(a) + "] = " + std::to_string(c) + " (0 = auto, else 2..64)");
    }
    if (s.maxProbesPerAxis < 2 || s.maxProbesPerAxis > kMaxProbesPerAxis)
        reject("maxProbesPerAxis = " + std::to_string(s.maxProbesPerAxis) + " (2..64)");
    if (s.raysPerProbe < 1 || s.raysPerProbe > kMaxRaysPerProbe)
        reject("raysPerProbe = " + std::to_string(s.raysPerProbe) + " (1..65536)");
    if (s.irradianceTexels < 1 || s.irradianceTexels > kMaxTexels)
        reject("irradianceTexels = " + std::to_string(s.irradianceTexels) + " (1..64)");
    if (s.distanceTexels < 1 || s.distanceTexels > kMaxTexels)
        reject("distanceTexels = " + std::to_string(s.distanceTexels) + " (1..64)");
    if (!inRange(s.hysteresis, 0.f, 1.f)) reject("hysteresis outside [0, 1]");
    if (!inRange(s.depthSharpness, 1.f, 1000.f)) reject("depthSharpness outside [1, 1000]");
    if (!inRange(s.irradianceGamma, 1.f, 16.f)) reject("irradianceGamma outside [1, 16]");
    if (!inRange(s.backfaceFractionInactive, 0.f, 1.f)) reject("backfaceFractionInactive outside [0, 1]");
    if (!inRange(s.relocationMaxOffset, 0.f, 0.5f)) reject("relocationMaxOffset outside [0, 0.5]");
    if (!inRange(s.relocationMinFrontDistance, 0.f, 0.5f)) reject("relocationMinFrontDistance outside [0, 0.5]");
    if (s.normalBias && !inRange(*s.normalBias, 0.f, kMaxCoordinate)) reject("normalBias negative or not finite");
    if (s.viewBias && !inRange(*s.viewBias, 0.f, kMaxCoordinate)) reject("viewBias negative or not finite");
    if (s.maxRayDistance && !(inRange(*s.maxRayDistance, 0.f, kMaxRayDistanceLimit) && *s.maxRayDistance > 0.f))
        reject("maxRayDistance outside (0, 1e18]");
}

std::vector<vec3> texelDirections(int n) {
    std::vector<vec3> dirs;
    dirs.reserve(static_cast<std::size_t>(n) * static_cast<std::size_t>(n));
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) dirs.push_back(ddgiTexelDirection(i, j, n));
    return dirs;
}

// Bilinear fetch from a bordered tile: the tile coordinate of `dir` lies in
// [1, N+1]^2 and texel centres are at x + 0.5, so the four taps stay inside.
template <typename T>
T sampleTile(const T* tile, int n, vec3 dir) {
    const vec2 c = ddgiTileCoord(dir, n) - vec2(0.5f);
    const int x0 = std::clamp(static_cast<int>(std::floor(c.x)), 0, n);
    const int y0 = std::clamp(static_cast<int>(std::floor(c.y)), 0, n);
    const float tx = std::clamp(c.x - static_cast<float>(x0), 0.f, 1.f);
    const float ty = std::clamp(c.y - static_cast<float>(y0), 0.f, 1.f);
    const T a = tile[ddgiTileIndex(x0, y0, n)], b = tile[ddgiTileIndex(x0 + 1, y0, n)];
    const T d = tile[ddgiTileIndex(x0, y0 + 1, n)], e = tile[ddgiTileIndex(x0 + 1, y0 + 1, n)];
    return (a * (1.f - tx) + b * tx) * (1.f - ty) + (d * (1.f - tx) + e * tx) * ty;
}

// One ray's result after classification.
struct Sample {
    vec3 radiance{0.f};
    float distance = 0.f;      // clamped to maxRayDistance
    float hitDistance = 0.f;   // unclamped |t| of a hit; +inf for a miss
    bool valid = false;        // false: rejected (non-finite)
    bool useRadiance = false;  // false for back faces
    bool backface = false;
};

// Scales `offset` back onto the ellipsoid with semi-axes `limit` when it
// lies outside it; a zero limit on an axis zeroes that component.
vec3 clampToEllipsoid(vec3 offset, vec3 limit) {
    vec3 q(0.f);
    for (int a = 0; a < 3; ++a) {
        if (!(limit[a] > 0.f)) offset[a] = 0.f;
        else q[a] = offset[a] / limit[a];
    }
    const float len2 = glm::dot(q, q);
    if (!(len2 > 1.f)) return offset;
    return offset / std::sqrt(len2);
}

bool insideEllipsoid(vec3 offset, vec3 limit) {
    float len2 = 0.f;
    for (int a = 0; a < 3; ++a) {
        if (!(limit[a] > 0.f)) {
            if (offset[a] != 0.f) return false;
            continue;
        }
        const float q = offset[a] / limit[a];
        len2 += q * q;
    }
    return len2 <= 1.f;
}

}  // namespace

DdgiVolume::DdgiVolume(const Aabb& sceneBounds, const DdgiSettings& settings) : settings_(settings) {
    validate(settings_);
    bounds_ = resolveBounds(sceneBounds);
    const vec3 extent = bounds_.extent();
    const float target = maxComponent(extent) / static_cast<float>(settings_.maxProbesPerAxis - 1);
    for (int a = 0; a < 3; ++a) {
        int c = settings_.probeCounts[a];
        if (c == 0) {
            const float cells = std::ceil(extent[a] / target);
            c = std::clamp(static_cast<int>(std::fmin(cells, 1e6f)) + 1, 2, settings_.maxProbesPerAxis);
        }
        counts_[a] = c;
        spacing_[a] = extent[a] / static_cast<float>(c - 1);
    }
    probeCount_ = static_cast<std::uint32_t>(counts_.x * counts_.y * counts_.z);
    const float minSpacing = minComponent(spacing_);
    normalBias_ = settings_.normalBias.value_or(0.045f * minSpacing);
    viewBias_ = settings_.viewBias.value_or(0.18f * minSpacing);
    maxRayDistance_ = settings_.maxRayDistance.value_or(std::fmin(1.5f * glm::length(spacing_), kMaxRayDistanceLimit));

    const std::size_t ti =
        static_cast<std::size_t>(irradianceTileSize()) * static_cast<std::size_t>(irradianceTileSize());
    const std::size_t td = static_cast<std::size_t>(distanceTileSize()) * static_cast<std::size_t>(distanceTileSize());
    irradiance_.resize(ti * probeCount_);
    distance_.resize(td * probeCount_);
    irradianceTexelDirs_ = texelDirections(settings_.irradianceTexels);
    distanceTexelDirs_ = texelDirections(settings_.distanceTexels);
    reset();
}

void DdgiVolume::reset() {
    std::fill(irradiance_.begin(), irradiance_.end(), vec3(0.f));
    std::fill(distance_.begin(), distance_.end(), vec2(maxRayDistance_, maxRayDistance_ * maxRayDistance_));
    updates_ = 0;
    lastStats_ = {};
    states_.assign(probeCount_, DdgiProbeState::Relocating);
    offsets_.assign(probeCount_, vec3(0.f));
    fresh_.assign(probeCount_, 1);
    moved_.assign(probeCount_, 0);
}

vec3 DdgiVolume::probeGridPosition(std::uint32_t probe) const {
    const int nx = counts_.x, ny = counts_.y;
    const int p = static_cast<int>(std::min(probe, probeCount_ - 1));
    const int x = p % nx, y = (p / nx) % ny, z = p / (nx * ny);
    return bounds_.lo + vec3(static_cast<float>(x), static_cast<float>(y), static_cast<float>(z)) * spacing_;
}

vec3 DdgiVolume::probeOffset(std::uint32_t probe) const { return offsets_[std::min(probe, probeCount_ - 1)]; }

vec3 DdgiVolume::probePosition(std::uint32_t probe) const { return probeGridPosition(probe) + probeOffset(probe); }

DdgiProbeState DdgiVolume::probeState(std::uint32_t probe) const {
    return probe < probeCount_ ? states_[probe] : DdgiProbeState::Active;
}

bool DdgiVolume::probeTraced(std::uint32_t probe) const {
    if (!settings_.classification) return true;
    const DdgiProbeState st = probeState(probe);
    return st == DdgiProbeState::Active || st == DdgiProbeState::Relocating;
}

std::uint32_t DdgiVolume::tracedProbeCount() const {
    std::uint32_t n = 0;
    for (std::uint32_t p = 0; p < probeCount_; ++p) n += probeTraced(p) ? 1u : 0u;
    return n;
}

Aabb DdgiVolume::probeInfluenceBox(std::uint32_t probe) const {
    const vec3 c = probeGridPosition(probe);
    const vec3 reach = spacing_ + vec3(normalBias_ + viewBias_);
    Aabb b;
    b.lo = c - reach;
    b.hi = c + reach;
    return b;
}

std::uint32_t DdgiVolume::wakeProbes(const Aabb& region) {
    if (region.empty()) return 0;
    std::uint32_t woken = 0;
    for (std::uint32_t p = 0; p < probeCount_; ++p) {
        if (states_[p] != DdgiProbeState::Idle && states_[p] != DdgiProbeState::Inside) continue;
        const Aabb b = probeInfluenceBox(p);
        if (glm::any(glm::lessThan(b.hi, region.lo)) || glm::any(glm::greaterThan(b.lo, region.hi))) continue;
        states_[p] = DdgiProbeState::Relocating;
        fresh_[p] = 1;
        ++woken;
    }
    return woken;
}

mat3 DdgiVolume::frameRotation(std::uint32_t frameIndex, std::uint32_t seed) {
    SampleKey key;
    key.pixel = kRotationKeyPixel;
    key.frame = frameIndex;
    key.seed = seed;
    return randomRotation(vec3(sampleUniform(key, 0), sampleUniform(key, 1), sampleUniform(key, 2)));
}

vec3 DdgiVolume::rayDirection(std::uint32_t /*probe*/, std::uint32_t ray, std::uint32_t frameIndex,
                              std::uint32_t seed) const {
    return sphericalFibonacci(ray, settings_.raysPerProbe, frameRotation(frameIndex, seed));
}

const vec3* DdgiVolume::irradianceTile(std::uint32_t probe) const {
    const std::size_t t =
        static_cast<std::size_t>(irradianceTileSize()) * static_cast<std::size_t>(irradianceTileSize());
    return irradiance_.data() + t * std::min(probe, probeCount_ - 1);
}

const vec2* DdgiVolume::distanceTile(std::uint32_t probe) const {
    const std::size_t t = static_cast<std::size_t>(distanceTileSize()) * static_cast<std::size_t>(distanceTileSize());
    return distance_.data() + t * std::min(probe, probeCount_ - 1);
}

vec3 DdgiVolume::decode(vec3 stored) const {
    if (settings_.irradianceGamma == 1.f) return stored;
    const float g = settings_.irradianceGamma;
    return {std::pow(std::fmax(stored.x, 0.f), g), std::pow(std::fmax(stored.y, 0.f), g),
            std::pow(std::fmax(stored.z, 0.f), g)};
}

void DdgiVolume::update(std::span<const DdgiRayResult> results, std::uint32_t frameIndex, std::uint32_t seed) {
    const std::uint32_t rays = settings_.raysPerProbe;
    const std::size_t expected = static_cast<std::size_t>(probeCount_) * rays;
    if (results.size() != expected)
        throw std::invalid_argument("DdgiVolume::update: " + std::to_string(results.size()) + " results, expected " +
                                    std::to_string(expected) + " (probes x raysPerProbe)");

    // The directions, hence the texel x ray weights, are the same for every
    // probe in the frame: compute them once.
    const mat3 rotation = frameRotation(frameIndex, seed);
    rayDirs_.resize(rays);
    for (std::uint32_t r = 0; r < rays; ++r) rayDirs_[r] = sphericalFibonacci(r, rays, rotation);
    const std::size_t ni = irradianceTexelDirs_.size(), nd = distanceTexelDirs_.size();
    irradianceWeights_.resize(ni * rays);
    distanceWeights_.resize(nd * rays);
    for (std::size_t t = 0; t < ni; ++t)
        for (std::uint32_t r = 0; r < rays; ++r)
            irradianceWeights_[t * rays + r] = std::fmax(0.f, glm::dot(irradianceTexelDirs_[t], rayDirs_[r]));
    for (std::size_t t = 0; t < nd; ++t)
        for (std::uint32_t r = 0; r < rays; ++r) {
            const float c = std::fmax(0.f, glm::dot(distanceTexelDirs_[t], rayDirs_[r]));
            distanceWeights_[t * rays + r] = c > 0.f ? std::pow(c, settings_.depthSharpness) : 0.f;
        }

    const float h = settings_.hysteresis;
    const float invGamma = 1.f / settings_.irradianceGamma;
    const int nIrr = settings_.irradianceTexels, nDist = settings_.distanceTexels;
    const std::size_t irrTile = static_cast<std::size_t>(nIrr + 2) * static_cast<std::size_t>(nIrr + 2);
    const std::size_t distTile = static_cast<std::size_t>(nDist + 2) * static_cast<std::size_t>(nDist + 2);
    const float maxDist = maxRayDistance_;
    const float minFront = settings_.relocationMinFrontDistance * minComponent(spacing_);
    const vec3 offsetLimit = settings_.relocationMaxOffset * spacing_;
    probeStats_.assign(probeCount_, DdgiUpdateStats{});
    moved_.assign(probeCount_, 0);
    std::vector<std::uint8_t> traced(probeCount_);
    for (std::uint32_t p = 0; p < probeCount_; ++p) traced[p] = probeTraced(p) ? 1 : 0;

    parallelForEach(probeCount_, [&](std::size_t p) {
        if (!traced[p]) return;  // Idle / Inside: nothing traced, nothing changes
        DdgiUpdateStats& stats = probeStats_[p];
        const DdgiRayResult* in = results.data() + p * rays;
        std::vector<Sample> samples(rays);
        for (std::uint32_t r = 0; r < rays; ++r) {
            const DdgiRayResult& res = in[r];
            Sample& s = samples[r];
            ++stats.rays;
            if (!isFinite(res.radiance) || std::isnan(res.distance)) {
                ++stats.rejectedSamples;
                continue;
            }
            const vec3 clamped = glm::clamp(res.radiance, vec3(0.f), vec3(kDdgiMaxRadiance));
            if (clamped != res.radiance) ++stats.clampedSamples;
            s.valid = true;
            s.radiance = clamped;
            if (std::isinf(res.distance)) {
                ++stats.misses;
                s.distance = maxDist;
                s.hitDistance = kInfinity;
                s.useRadiance = true;
            } else if (res.distance < 0.f) {
                ++stats.backfaceHits;
                s.distance = std::fmin(-res.distance, maxDist);
                s.hitDistance = -res.distance;
                s.useRadiance = false;
                s.backface = true;
            } else {
                s.distance = std::fmin(res.distance, maxDist);
                s.hitDistance = res.distance;
                s.useRadiance = true;
            }
        }
        const bool inside = static_cast<double>(stats.backfaceHits) >
                            static_cast<double>(settings_.backfaceFractionInactive) * static_cast<double>(stats.rays);

        // What the rays saw: the closest back and front faces, and whether a
        // surface lies in the probe's influence box (hit points from the
        // position the rays were traced from).
        const vec3 origin = probePosition(static_cast<std::uint32_t>(p));
        const Aabb influence = probeInfluenceBox(static_cast<std::uint32_t>(p));
        float closestBack = kInfinity, closestFront = kInfinity;
        int backRay = -1, frontRay = -1;
        bool surfaceNear = false;
        for (std::uint32_t r = 0; r < rays; ++r) {
            const Sample& s = samples[r];
            if (!s.valid || std::isinf(s.hitDistance)) continue;
            if (s.backface && s.hitDistance < closestBack) closestBack = s.hitDistance, backRay = static_cast<int>(r);
            if (!s.backface && s.hitDistance < closestFront)
                closestFront = s.hitDistance, frontRay = static_cast<int>(r);
            if (!surfaceNear) {
                const vec3 hit = origin + rayDirs_[r] * s.hitDistance;
                surfaceNear = glm::all(glm::greaterThanEqual(hit, influence.lo)) &&
                              glm::all(glm::lessThanEqual(hit, influence.hi));
            }
        }

        if (!inside) {
            const bool history = fresh_[p] == 0;
            // Irradiance: pi x cosine-weighted mean radiance around each texel.
            std::span<vec3> irr(irradiance_.data() + p * irrTile, irrTile);
            for (int j = 0; j < nIrr; ++j) {
                for (int i = 0; i < nIrr; ++i) {
                    const float* w = irradianceWeights_.data() + (static_cast<std::size_t>(j) * nIrr + i) * rays;
                    double sr = 0.0, sg = 0.0, sb = 0.0, sw = 0.0;
                    for (std::uint32_t r = 0; r < rays; ++r) {
                        const Sample& s = samples[r];
                        if (!s.useRadiance || !(w[r] > 0.f)) continue;
                        sr += static_cast<double>(w[r]) * s.radiance.x;
                        sg += static_cast<double>(w[r]) * s.radiance.y;
                        sb += static_cast<double>(w[r]) * s.radiance.z;
                        sw += w[r];
                    }
                    if (!(sw > 0.0)) continue;  // nothing seen around this texel: keep the old value
                    vec3 value(static_cast<float>(kPiD * sr / sw), static_cast<float>(kPiD * sg / sw),
                               static_cast<float>(kPiD * sb / sw));
                    if (invGamma != 1.f)
                        value =
                            vec3(std::pow(value.x, invGamma), std::pow(value.y, invGamma), std::pow(value.z, invGamma));
                    vec3& texel = irr[ddgiTileIndex(i + 1, j + 1, nIrr)];
                    texel = history ? texel * h + value * (1.f - h) : value;
                }
            }
            ddgiFillTileBorder(irr, nIrr);

            // Distance moments with the sharp lobe; back faces count with |d|.
            std::span<vec2> dist(distance_.data() + p * distTile, distTile);
            for (int j = 0; j < nDist; ++j) {
                for (int i = 0; i < nDist; ++i) {
                    const float* w = distanceWeights_.data() + (static_cast<std::size_t>(j) * nDist + i) * rays;
                    double sd = 0.0, sd2 = 0.0, sw = 0.0;
                    for (std::uint32_t r = 0; r < rays; ++r) {
                        const Sample& s = samples[r];
                        if (!s.valid || !(w[r] > 0.f)) continue;
                        const double d = s.distance;
                        sd += w[r] * d;
                        sd2 += w[r] * d * d;
                        sw += w[r];
                    }
                    if (!(sw > 0.0)) continue;
                    const vec2 value(static_cast<float>(sd / sw), static_cast<float>(sd2 / sw));
                    vec2& texel = dist[ddgiTileIndex(i + 1, j + 1, nDist)];
                    texel = history ? texel * h + value * (1.f - h) : value;
                }
            }
            ddgiFillTileBorder(dist, nDist);
            fresh_[p] = 0;
        }

        // Relocation and classification (DdgiSettings::relocation, ::classification).
        vec3 offset = offsets_[p];
        DdgiProbeState state;
        if (inside) {
            fresh_[p] = 1;  // what it saw from inside is no history for where it goes
            state = DdgiProbeState::Inside;
            if (settings_.relocation && backRay >= 0) {
                const vec3 candidate = offset + rayDirs_[static_cast<std::size_t>(backRay)] * (closestBack + minFront);
                if (isFinite(candidate) && insideEllipsoid(candidate, offsetLimit)) {
                    offset = candidate;
                    state = DdgiProbeState::Relocating;
                }
            }
        } else {
            state = !settings_.classification || surfaceNear ? DdgiProbeState::Active : DdgiProbeState::Idle;
            if (settings_.relocation) {
                if (frontRay >= 0 && closestFront < minFront) {
                    // Too close: away from the closest front face, along the
                    // ray most opposite to it, at most half its free distance.
                    const vec3 away = -rayDirs_[static_cast<std::size_t>(frontRay)];
                    std::uint32_t best = 0;
                    float bestCos = -2.f;
                    for (std::uint32_t r = 0; r < rays; ++r) {
                        const float c = glm::dot(rayDirs_[r], away);
                        if (samples[r].valid && c > bestCos) bestCos = c, best = r;
                    }
                    const float freeDistance = std::fmin(samples[best].hitDistance, maxDist);
                    const float step = std::fmin(minFront - closestFront, 0.5f * freeDistance);
                    const vec3 candidate = clampToEllipsoid(offset + rayDirs_[best] * step, offsetLimit);
                    if (isFinite(candidate)) offset = candidate;
                } else if (offset != vec3(0.f) && std::fmin(closestFront, closestBack) > 1.25f * minFront) {
                    // Clear: back toward the grid point, keeping 1.25 minFront from everything seen.
                    const float len = glm::length(offset);
                    const float step = std::fmin(std::fmin(closestFront, closestBack) - 1.25f * minFront, len);
                    offset = step >= len ? vec3(0.f) : offset - offset * (step / len);
                }
            }
        }
        moved_[p] = offset != offsets_[p] ? 1 : 0;
        offsets_[p] = offset;
        states_[p] = state;
    });

    // Fixed-order reduction of the per-probe counters.
    lastStats_ = {};
    for (std::uint32_t p = 0; p < probeCount_; ++p) {
        const DdgiUpdateStats& s = probeStats_[p];
        lastStats_.rays += s.rays;
        lastStats_.misses += s.misses;
        lastStats_.backfaceHits += s.backfaceHits;
        lastStats_.rejectedSamples += s.rejectedSamples;
        lastStats_.clampedSamples += s.clampedSamples;
        lastStats_.tracedProbes += traced[p];
        lastStats_.movedProbes += moved_[p];
        lastStats_.offsetProbes += offsets_[p] != vec3(0.f) ? 1u : 0u;
        switch (states_[p]) {
            case DdgiProbeState::Active: ++lastStats_.activeProbes; break;
            case DdgiProbeState::Relocating: ++lastStats_.relocatingProbes; break;
            case DdgiProbeState::Inside: ++lastStats_.insideProbes; break;
            case DdgiProbeState::Idle: ++lastStats_.idleProbes; break;
        }
    }
    ++updates_;
}

vec3 DdgiVolume::probeIrradiance(std::uint32_t probe, vec3 direction) const {
    return decode(sampleTile(irradianceTile(probe), settings_.irradianceTexels, direction));
}

vec2 DdgiVolume::probeDistanceMoments(std::uint32_t probe, vec3 direction) const {
    return sampleTile(distanceTile(probe), settings_.distanceTexels, direction);
}

vec3 DdgiVolume::irradiance(vec3 position, vec3 normal, vec3 viewDir) const {
    if (!isFinite(position)) return vec3(0.f);
    position = clampVec(position, kMaxQueryCoordinate);
    const vec3 n = normalizeOr(normal, vec3(0.f, 0.f, 1.f));
    const vec3 v = normalizeOr(viewDir, vec3(0.f));
    const vec3 biased = position + normalBias_ * n + viewBias_ * v;

    // Cell of the biased point, clamped to the grid.
    glm::ivec3 base;
    vec3 alpha;
    for (int a = 0; a < 3; ++a) {
        const float g = std::clamp((biased[a] - bounds_.lo[a]) / spacing_[a], -1.f, static_cast<float>(counts_[a]));
        base[a] = std::clamp(static_cast<int>(std::floor(g)), 0, counts_[a] - 2);
        alpha[a] = std::clamp(g - static_cast<float>(base[a]), 0.f, 1.f);
    }

    // Inactive probes (inside geometry) are skipped unless all eight are.
    bool anyActive = false;
    for (int c = 0; c < 8; ++c) {
        const glm::ivec3 g = base + glm::ivec3(c & 1, (c >> 1) & 1, (c >> 2) & 1);
        anyActive = anyActive || probeActive(static_cast<std::uint32_t>(g.x + counts_.x * (g.y + counts_.y * g.z)));
    }
    vec3 sum(0.f);
    float sumWeight = 0.f;
    for (int c = 0; c < 8; ++c) {
        const glm::ivec3 offset(c & 1, (c >> 1) & 1, (c >> 2) & 1);
        const glm::ivec3 g = base + offset;
        const auto probe = static_cast<std::uint32_t>(g.x + counts_.x * (g.y + counts_.y * g.z));
        if (anyActive && !probeActive(probe)) continue;
        const vec3 probePos = probePosition(probe);

        // Smooth back-face weight, from the true (unbiased) position.
        const vec3 toProbe = normalizeOr(probePos - position, vec3(0.f));
        const float facing = (glm::dot(toProbe, n) + 1.f) * 0.5f;
        float weight = facing * facing + kBackfaceFloor;

        // Chebyshev visibility of the biased point from the probe.
        vec3 probeToPoint = biased - probePos;
        const vec3 dir = normalizeOr(probeToPoint, vec3(0.f, 0.f, 1.f));
        const float dist = glm::length(probeToPoint);
        const vec2 moments = probeDistanceMoments(probe, dir);
        const float mean = moments.x;
        const float variance = std::fabs(mean * mean - moments.y);
        if (dist > mean) {
            const float diff = dist - mean;
            const float denom = variance + diff * diff;
            float chebyshev = denom > 0.f ? variance / denom : 0.f;
            chebyshev = chebyshev * chebyshev * chebyshev;
            weight *= std::fmax(chebyshev, 0.f);
        }
        weight = std::fmax(weight, kMinProbeWeight);
        if (weight < kCrushThreshold) weight *= weight * weight / (kCrushThreshold * kCrushThreshold);

        const vec3 tri = glm::mix(vec3(1.f) - alpha, alpha, vec3(offset));
        weight *= tri.x * tri.y * tri.z;

        sum += weight * probeIrradiance(probe, n);
        sumWeight += weight;
    }
    // With a probe used, sumWeight >= its minimum weight x its trilinear weight;
    // that can be 0 when only zero-trilinear-weight probes are active.
    if (!(sumWeight > 0.f)) return vec3(0.f);
    const vec3 result = sum / sumWeight;
    return isFinite(result) ? result : vec3(0.f);
}

namespace {

// Probe tiles laid out as the atlas: probe p at column p % columns, row
// p / columns; texel(p, index within the tile) gives the texel's value.
template <class Texel>
DdgiAtlasImage atlasOfTiles(std::uint32_t probeCount, int columns, int rows, int tile, Texel&& texel) {
    DdgiAtlasImage img;
    img.width = columns * tile;
    img.height = rows * tile;
    img.texels.resize(static_cast<std::size_t>(img.width) * static_cast<std::size_t>(img.height));
    for (std::uint32_t p = 0; p < probeCount; ++p) {
        const int x0 = static_cast<int>(p) % columns * tile, y0 = static_cast<int>(p) / columns * tile;
        for (int y = 0; y < tile; ++y)
            for (int x = 0; x < tile; ++x)
                img.texels[static_cast<std::size_t>(y0 + y) * img.width + (x0 + x)] =
                    texel(p, static_cast<std::size_t>(y) * tile + x);
    }
    return img;
}

}  // namespace

DdgiAtlasImage DdgiVolume::irradianceAtlasImage() const {
    return atlasOfTiles(probeCount_, counts_.x * counts_.y, counts_.z, irradianceTileSize(),
                        [&](std::uint32_t p, std::size_t t) { return decode(irradianceTile(p)[t]); });
}

DdgiAtlasImage DdgiVolume::distanceAtlasImage() const {
    return atlasOfTiles(probeCount_, counts_.x * counts_.y, counts_.z, distanceTileSize(),
                        [&](std::uint32_t p, std::size_t t) { return vec3(distanceTile(p)[t], 0.f); });
}

std::size_t DdgiVolume::bytesAllocated() const {
    return irradiance_.capacity() * sizeof(vec3) + distance_.capacity() * sizeof(vec2) +
           (irradianceTexelDirs_.capacity() + distanceTexelDirs_.capacity() + rayDirs_.capacity()) * sizeof(vec3) +
           (irradianceWeights_.capacity() + distanceWeights_.capacity()) * sizeof(float) +
           probeStats_.capacity() * sizeof(DdgiUpdateStats) + states_.capacity() * sizeof(DdgiProbeState) +
           offsets_.capacity() * sizeof(vec3) + fresh_.capacity() + moved_.capacity();
}

}  // namespace rtlab::shaders
