#pragma once
// One ray through the model's two-level BVH, read from the model's memory
// image (format.hpp): the same steps in the same order as
// rtcore_sim::RayTraversal (docs/rtcore-model.md, "Traversal"), with the
// same float operations, so that hits and per-ray counters are identical.
// Compiled twice: by nvcc for the GPU (gpucheck.cu, with --fmad=false) and
// by the host compiler for the host twin that CI tests against the model
// (ISO C++, no FMA contraction). Every fetch reads all the bytes the timing
// model's node cache reads for that step (a whole node, a whole leaf, a
// whole instance descriptor), word by word, into the ray's checksum, so
// the GPU's loads are the model's fetch stream.
#include <gpucheck/format.hpp>

#include <cstdint>

#if defined(__CUDACC__)
#define GC_HD __host__ __device__ __forceinline__
#define GC_UNROLL _Pragma("unroll")
#else
#define GC_HD inline
#define GC_UNROLL
#endif

namespace gpucheck {

enum EntryKind : std::uint32_t { kTlasRef = 0, kBlasRef = 1, kInstance = 2 };

namespace detail {

GC_HD float absf(float x) { return x < 0.f ? -x : x; }
// a[k] for k in 0..2 with constant indices only (on the GPU a run-time
// index would put the array in local memory, which goes through the L1).
GC_HD float sel3(const float* a, int k) { return k == 0 ? a[0] : (k == 1 ? a[1] : a[2]); }
GC_HD float maxAbs3(float x, float y, float z) {
    float m = absf(x);  // std::max({a, b, c}): the first largest
    if (m < absf(y)) m = absf(y);
    if (m < absf(z)) m = absf(z);
    return m;
}
// tracer::conservativeBoxPadding
GC_HD float boxPadding(float boxMagnitude, float originMagnitude) {
    return 0x1p-18f * (boxMagnitude + originMagnitude);
}
GC_HD bool signBit(float x) {
#if defined(__CUDA_ARCH__)
    return signbit(x);
#else
    return __builtin_signbit(x);
#endif
}
GC_HD std::uint32_t floatBits(float f) {
#if defined(__CUDA_ARCH__)
    return static_cast<std::uint32_t>(__float_as_uint(f));
#else
    return __builtin_bit_cast(std::uint32_t, f);
#endif
}
GC_HD float bitsFloat(std::uint32_t u) {
#if defined(__CUDA_ARCH__)
    return __uint_as_float(u);
#else
    return __builtin_bit_cast(float, u);
#endif
}
// tracer::tieInclusiveUpperBound: one float up (t is finite and >= 0 here;
// +inf stays +inf).
GC_HD float nextUp(float t) {
    if (t >= 0.f && t < bitsFloat(0x7f800000u)) return bitsFloat(floatBits(t) + 1u);
    if (t == bitsFloat(0x7f800000u)) return t;
    if (t == 0.f) return bitsFloat(1u);
    return bitsFloat(floatBits(t) - 1u);  // negative finite
}

struct SpaceRay {
    float o[3], d[3], inv[3];
    float padding;
};

// rtcore_sim's slabTest.
GC_HD bool slabTest(const float lo[3], const float hi[3], const SpaceRay& r, float tMin, float tMax, float farScale,
                    float& tEntry) {
    float tNear = tMin, tFar = tMax;
    GC_UNROLL
    for (int a = 0; a < 3; ++a) {
        const bool negative = signBit(r.inv[a]);
        const float nearPlane = negative ? hi[a] + r.padding : lo[a] - r.padding;
        const float farPlane = negative ? lo[a] - r.padding : hi[a] + r.padding;
        const float tA = (nearPlane - r.o[a]) * r.inv[a];
        const float tB = (farPlane - r.o[a]) * r.inv[a] * farScale;
        tNear = tA > tNear ? tA : tNear;
        tFar = tB < tFar ? tB : tFar;
    }
    tEntry = tNear;
    return tNear <= tFar;
}

// tracer::makeWatertightRay + intersectTriangleWatertight, operation for operation.
struct WatertightRay {
    int kx, ky, kz;
    float ox, oy, oz, sx, sy, sz;
    bool valid;
};
GC_HD WatertightRay makeWatertightRay(const float o[3], const float d[3]) {
    WatertightRay r{0, 1, 2, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f, false};
    int kz = 0;
    if (absf(d[1]) > absf(d[0])) kz = 1;
    if (absf(d[2]) > absf(sel3(d, kz))) kz = 2;
    const float dkz = sel3(d, kz);
    if (!(absf(dkz) > 0.f)) return r;
    int kx = kz == 2 ? 0 : kz + 1, ky = kx == 2 ? 0 : kx + 1;
    if (dkz < 0.f) {
        const int s = kx;
        kx = ky;
        ky = s;
    }
    r.kx = kx;
    r.ky = ky;
    r.kz = kz;
    r.ox = sel3(o, kx);
    r.oy = sel3(o, ky);
    r.oz = sel3(o, kz);
    r.sx = sel3(d, kx) / dkz;
    r.sy = sel3(d, ky) / dkz;
    r.sz = 1.f / dkz;
    r.valid = true;
    return r;
}
GC_HD bool intersectTriangle(const WatertightRay& r, const float* a, const float* b, const float* c, float tMin,
                             float tMax, float& tOut, float& b1Out, float& b2Out) {
    if (!r.valid) return false;
    const float akx = sel3(a, r.kx) - r.ox, aky = sel3(a, r.ky) - r.oy, akz = sel3(a, r.kz) - r.oz;
    const float bkx = sel3(b, r.kx) - r.ox, bky = sel3(b, r.ky) - r.oy, bkz = sel3(b, r.kz) - r.oz;
    const float ckx = sel3(c, r.kx) - r.ox, cky = sel3(c, r.ky) - r.oy, ckz = sel3(c, r.kz) - r.oz;
    const float ax = akx - r.sx * akz, ay = aky - r.sy * akz;
    const float bx = bkx - r.sx * bkz, by = bky - r.sy * bkz;
    const float cx = ckx - r.sx * ckz, cy = cky - r.sy * ckz;
    const float u = cx * by - cy * bx;
    const float v = ax * cy - ay * cx;
    const float w = bx * ay - by * ax;
    if ((u < 0.f || v < 0.f || w < 0.f) && (u > 0.f || v > 0.f || w > 0.f)) return false;
    const float det = u + v + w;
    if (det == 0.f) return false;
    const float az = r.sz * akz, bz = r.sz * bkz, cz = r.sz * ckz;
    const float t = (u * az + v * bz + w * cz) / det;
    if (!(t > tMin && t < tMax)) return false;
    tOut = t;
    b1Out = v / det;
    b2Out = w / det;
    return true;
}

}  // namespace detail

// The scene as the traversal reads it: the image as 32-bit words, and the
// header. The side tables (meshes, exact instance transforms) come through a
// Tables object: mesh(i), instance(i); on the GPU they sit in constant
// memory, outside the caches the check measures.
struct SceneView {
    const std::uint32_t* image;
    SceneHeader header;
};
struct HostTables {
    const MeshInfo* meshes;
    const InstanceInfo* instances;
    GC_HD const MeshInfo& mesh(std::uint32_t i) const { return meshes[i]; }
    GC_HD const InstanceInfo& instance(std::uint32_t i) const { return instances[i]; }
};

// Reads the image word by word, folding each word into the ray's checksum
// and counting the fetch's bytes and 32-byte sectors.
// Every fetch is checked to lie in the image before its words are read (a
// corrupt export is found per fetch, not per word: the inner loads stay plain).
struct Fetcher {
    const std::uint32_t* image;
    std::uint64_t imageBytes;
    std::uint32_t checksum = 0x811c9dc5u;
    std::uint32_t bytes = 0, sectors = 0;
    GC_HD bool inImage(std::uint64_t address, std::uint64_t size) const {
        return address <= imageBytes && size <= imageBytes - address;
    }
    GC_HD std::uint32_t word(std::uint64_t address) {
        const std::uint32_t w = image[address >> 2];
        checksum = (checksum ^ w) * 0x01000193u;
        return w;
    }
    // Counts a fetch of `size` bytes at `address`; false when it is not in the image.
    GC_HD bool count(std::uint64_t address, std::uint64_t size) {
        if (!inImage(address, size)) return false;
        bytes += static_cast<std::uint32_t>(size);
        sectors += static_cast<std::uint32_t>(((address + size - 1) >> 5) - (address >> 5) + 1);
        return true;
    }
};

// At most this many steps a ray: more means a corrupt export (a cycle of references).
inline constexpr std::uint32_t kMaxSteps = 1u << 24;

// The traversal of one ray. Stack: push(bits, tEntry, kind) -> false when
// it is full, pop(bits, tEntry, kind) (only when not empty), clear(); on the
// GPU a fixed number of entries in shared memory, the rest in global memory
// (as deep as the model's deepest stack); on the host a bounded vector.
// Returns false for a corrupt export (an address outside the image, a mesh
// or instance that does not exist, a leaf larger than the image, a cycle):
// the answer is then meaningless. A ray that takes maxSteps steps or fills
// the stack stops there (maxStackDepth ~0 for a full stack): it differs
// from the model's answer, which is how a divergence is reported.
template <class Stack, class Tables>
GC_HD bool traceRay(const SceneView& scene, const Tables& tables, const RayIn& ray, Stack& stack, RayOut& out,
                    std::uint32_t maxSteps = kMaxSteps) {
    using namespace detail;
    const SceneHeader& h = scene.header;
    Fetcher f{scene.image, h.imageBytes};
    out = RayOut{};
    out.t = bitsFloat(0x7f800000u);
    float tClosest = ray.tMax;
    bool hit = false;
    std::uint32_t hitInstance = 0, hitGeometry = 0, hitPrimitive = 0;
    float hitT = out.t, hitB1 = 0.f, hitB2 = 0.f;

    // Step: the world ray and its TLAS padding.
    SpaceRay world;
    GC_UNROLL
    for (int a = 0; a < 3; ++a) {
        world.o[a] = ray.origin[a];
        world.d[a] = ray.direction[a];
        world.inv[a] = 1.f / ray.direction[a];
    }
    world.padding = boxPadding(h.tlasMagnitude, 3.f * h.tlasConditioning * maxAbs3(world.o[0], world.o[1], world.o[2]));
    SpaceRay object = world;
    WatertightRay objectTri = makeWatertightRay(object.o, object.d);
    std::uint32_t instanceIndex = 0;
    const MeshInfo* mesh = nullptr;
    std::uint32_t depth = 0;  // entries on the stack

    bool finished = h.tlasRoot == kInvalidRef;
    std::uint32_t curBits = h.tlasRoot, curKind = kTlasRef;
    float curT = ray.tMin;

    bool stackFull = false;
    auto push = [&](std::uint32_t bits, float t, std::uint32_t kind) {
        if (!stack.push(bits, t, kind)) {
            stackFull = true;
            return;
        }
        ++depth;
        if (depth > out.maxStackDepth) out.maxStackDepth = depth;
    };
    auto selectNext = [&]() {
        std::uint32_t bits, kind;
        float t;
        while (depth > 0) {
            stack.pop(bits, t, kind);
            --depth;
            if (t > tClosest) continue;
            curBits = bits;
            curT = t;
            curKind = kind;
            return;
        }
        finished = true;
    };

    while (!finished) {
        if (out.steps == kMaxSteps) return false;
        if (stackFull) {
            out.maxStackDepth = ~0u;
            break;
        }
        if (out.steps == maxSteps) break;
        ++out.steps;
        // Step: instance transition, the ray into the instance's object space.
        if (curKind == kInstance) {
            instanceIndex = curBits;
            const std::uint64_t at = h.instanceBase + 64ull * instanceIndex;
            if (!f.count(at, 64)) return false;
            std::uint32_t meshIndex = 0;
            GC_UNROLL
            for (std::uint32_t i = 0; i < 16; ++i) {
                const std::uint32_t w = f.word(at + 4 * i);
                if (i == 12) meshIndex = w;
            }
            if (meshIndex >= h.meshCount || instanceIndex >= h.instanceCount) return false;
            mesh = &tables.mesh(meshIndex);
            ++out.instanceTransitions;
            const double(*m)[3] = tables.instance(instanceIndex).objectFromWorld;
            const double x = world.o[0], y = world.o[1], z = world.o[2];
            const double dx = world.d[0], dy = world.d[1], dz = world.d[2];
            GC_UNROLL
            for (int r = 0; r < 3; ++r) {
                object.o[r] = static_cast<float>(((m[0][r] * x + m[1][r] * y) + m[2][r] * z) + m[3][r]);
                object.d[r] = static_cast<float>((m[0][r] * dx + m[1][r] * dy) + m[2][r] * dz);
            }
            GC_UNROLL
            for (int a = 0; a < 3; ++a) object.inv[a] = 1.f / object.d[a];
            object.padding = boxPadding(mesh->magnitude, maxAbs3(object.o[0], object.o[1], object.o[2]));
            objectTri = makeWatertightRay(object.o, object.d);
            if (mesh->root == kInvalidRef) {
                selectNext();
                continue;
            }
            curBits = mesh->root;
            curKind = kBlasRef;
            continue;
        }

        const bool inTlas = curKind == kTlasRef;
        const SpaceRay space = inTlas ? world : object;  // a copy: a reference would put both in local memory
        const std::uint64_t nodeBase = inTlas ? h.tlasNodeBase : mesh->nodeBase;
        const std::uint64_t leafBase = inTlas ? h.tlasLeafBase : mesh->leafBase;

        if ((curBits & kLeafBit) == 0) {
            // Step: internal node, every child box tested; the nearest hit
            // child next, the others pushed far to near (ties keep slot order).
            ++out.nodeVisits;
            const std::uint64_t at = nodeBase + std::uint64_t(h.nodeBytes) * curBits;
            if (!f.count(at, h.nodeBytes)) return false;
            const std::uint32_t childCount = f.word(at);
            GC_UNROLL
            for (std::uint32_t i = 1; i < 4; ++i) f.word(at + 4 * i);
            // Every slot's words are read (the model fetches the whole node);
            // hit children get their entry distance, the others +inf and last.
            std::uint32_t hitBits[kMaxWidth];
            float hitTs[kMaxWidth];
            bool hitOk[kMaxWidth];
            std::uint32_t hitCount = 0;
            GC_UNROLL
            for (std::uint32_t i = 0; i < kMaxWidth; ++i) {
                hitOk[i] = false;
                hitTs[i] = 0.f;
                hitBits[i] = kInvalidRef;
                if (i >= h.width) continue;
                const std::uint64_t c = at + 16 + 28ull * i;
                float lo[3], hi[3];
                GC_UNROLL
                for (int a = 0; a < 3; ++a) lo[a] = bitsFloat(f.word(c + 4 * a));
                GC_UNROLL
                for (int a = 0; a < 3; ++a) hi[a] = bitsFloat(f.word(c + 12 + 4 * a));
                const std::uint32_t bits = f.word(c + 24);
                if (i >= childCount) continue;
                float tEntry;
                if (!slabTest(lo, hi, space, ray.tMin, tClosest, h.farScale, tEntry)) continue;
                hitOk[i] = true;
                hitTs[i] = tEntry;
                hitBits[i] = bits;
                ++hitCount;
            }
            // Nearest first; ties keep slot order (a stable sort, as the model's insertion sort).
            GC_UNROLL
            for (std::uint32_t pass = 0; pass + 1 < kMaxWidth; ++pass) {
                GC_UNROLL
                for (std::uint32_t j = 0; j + 1 < kMaxWidth - pass; ++j) {
                    const bool swap = hitOk[j + 1] && (!hitOk[j] || hitTs[j] > hitTs[j + 1]);
                    if (swap) {
                        const float t = hitTs[j];
                        hitTs[j] = hitTs[j + 1];
                        hitTs[j + 1] = t;
                        const std::uint32_t b = hitBits[j];
                        hitBits[j] = hitBits[j + 1];
                        hitBits[j + 1] = b;
                        const bool o = hitOk[j];
                        hitOk[j] = hitOk[j + 1];
                        hitOk[j + 1] = o;
                    }
                }
            }
            if (hitCount == 0) {
                selectNext();
                continue;
            }
            GC_UNROLL
            for (std::uint32_t k = kMaxWidth - 1; k >= 1; --k)
                if (k < hitCount) push(hitBits[k], hitTs[k], curKind);
            curBits = hitBits[0];
            curT = hitTs[0];
            continue;
        }

        ++out.leafVisits;
        const std::uint64_t at = leafBase + (curBits & ~kLeafBit);
        if (!f.inImage(at, 8)) return false;
        const std::uint32_t refCount = f.word(at);
        f.word(at + 4);
        if (refCount > (inTlas ? kMaxTlasLeafRefs : std::uint32_t(h.imageBytes / 44))) return false;
        if (inTlas) {
            // Step: TLAS leaf, the instances passing the mask entered in
            // reference order (the later ones wait on the stack).
            if (!f.count(at, 8 + 4ull * refCount)) return false;
            // Which references pass the mask, as bits (no array: see sel3);
            // the later ones are pushed from their words read again.
            std::uint32_t enteredMask = 0, first = 0;
            for (std::uint32_t r = 0; r < refCount; ++r) {
                const std::uint32_t w = f.word(at + 8 + 4 * r);
                if ((ray.mask & (w >> kInstanceIndexBits)) != 0) {
                    if (enteredMask == 0) first = w & ((1u << kInstanceIndexBits) - 1u);
                    enteredMask |= 1u << r;
                }
            }
            if (enteredMask == 0) {
                selectNext();
                continue;
            }
            for (std::uint32_t r = refCount; r-- > 0;) {
                if (!((enteredMask >> r) & 1u) || (enteredMask & ((1u << r) - 1u)) == 0) continue;
                push(scene.image[(at + 8 + 4 * r) >> 2] & ((1u << kInstanceIndexBits) - 1u), curT, kInstance);
            }
            curBits = first;
            curKind = kInstance;
            continue;
        }
        // Step: BLAS leaf, every triangle in reference order; a committed
        // candidate is the closest hit, later tests use its t.
        if (!f.count(at, 8 + 44ull * refCount)) return false;
        bool ended = false;
        for (std::uint32_t r = 0; r < refCount; ++r) {
            const std::uint64_t s = at + 8 + 44ull * r;
            float v[9];
            GC_UNROLL
            for (int k = 0; k < 9; ++k) v[k] = bitsFloat(f.word(s + 4 * k));
            const std::uint32_t geometry = f.word(s + 36), primitive = f.word(s + 40);
            if (ended || ray.skipTriangles) continue;
            ++out.triangleTests;
            float t, b1, b2;
            if (!intersectTriangle(objectTri, v, v + 3, v + 6, ray.tMin, hit ? nextUp(tClosest) : tClosest, t, b1, b2))
                continue;
            // rtlab's tie rule (tracer/hit_order.hpp): the smaller (instance, geometry, primitive) wins.
            if (hit && !(t < tClosest || (instanceIndex != hitInstance ? instanceIndex < hitInstance
                                          : geometry != hitGeometry    ? geometry < hitGeometry
                                                                       : primitive < hitPrimitive)))
                continue;
            tClosest = t;
            hit = true;
            hitT = t;
            hitB1 = b1;
            hitB2 = b2;
            hitInstance = instanceIndex;
            hitGeometry = geometry;
            hitPrimitive = primitive;
            if (ray.policy == kFirstHit) ended = true;
        }
        if (ended) {
            stack.clear();  // the search ends: the stack is dropped
            depth = 0;
            finished = true;
            continue;
        }
        selectNext();
    }
    out.hit = hit ? 1u : 0u;
    out.t = hitT;
    out.b1 = hitB1;
    out.b2 = hitB2;
    out.instance = hitInstance;
    out.geometry = hitGeometry;
    out.primitive = hitPrimitive;
    out.fetchBytes = f.bytes;
    out.fetchSectors = f.sectors;
    out.checksum = f.checksum;
    return true;
}

}  // namespace gpucheck
