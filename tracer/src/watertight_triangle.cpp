#include <rtlab/core/simd.hpp>
#include <rtlab/tracer/watertight_triangle.hpp>

#include <bit>
#include <cmath>
#include <utility>

namespace rtlab::tracer {

WatertightRay makeWatertightRay(const vec3& origin, const vec3& direction) {
    WatertightRay r;
    // Plain pointers: glm's vec3::operator[] is a switch.
    const float* d = &direction.x;
    const float* o = &origin.x;
    // Step: permute so that z is the dominant direction axis; swapping x and y
    // when d.z < 0 keeps the winding.
    int kz = 0;
    if (std::abs(d[1]) > std::abs(d[kz])) kz = 1;
    if (std::abs(d[2]) > std::abs(d[kz])) kz = 2;
    if (!(std::abs(d[kz]) > 0.f)) return r;  // zero or NaN direction
    int kx = kz == 2 ? 0 : kz + 1, ky = kx == 2 ? 0 : kx + 1;
    if (d[kz] < 0.f) std::swap(kx, ky);
    r.kx = kx;
    r.ky = ky;
    r.kz = kz;
    r.ox = o[kx];
    r.oy = o[ky];
    r.oz = o[kz];
    // Step: the shear that makes the ray run along +z.
    r.sx = d[kx] / d[kz];
    r.sy = d[ky] / d[kz];
    r.sz = 1.f / d[kz];
    r.valid = true;
    return r;
}

std::optional<TriangleHit> intersectTriangleWatertight(const WatertightRay& r, const vec3& p0, const vec3& p1,
                                                       const vec3& p2, float tMin, float tMax) {
    if (!r.valid) return std::nullopt;
    const float* a = &p0.x;
    const float* b = &p1.x;
    const float* c = &p2.x;
    // Step: translate to the ray origin, permute, shear (the same operations
    // in the same order as the cluster form below).
    const float akx = a[r.kx] - r.ox, aky = a[r.ky] - r.oy, akz = a[r.kz] - r.oz;
    const float bkx = b[r.kx] - r.ox, bky = b[r.ky] - r.oy, bkz = b[r.kz] - r.oz;
    const float ckx = c[r.kx] - r.ox, cky = c[r.ky] - r.oy, ckz = c[r.kz] - r.oz;
    const float ax = akx - r.sx * akz, ay = aky - r.sy * akz;
    const float bx = bkx - r.sx * bkz, by = bky - r.sy * bkz;
    const float cx = ckx - r.sx * ckz, cy = cky - r.sy * ckz;
    // Step: edge functions; the same edge in two triangles gives exactly negated values.
    const float u = cx * by - cy * bx;
    const float v = ax * cy - ay * cx;
    const float w = bx * ay - by * ax;
    if ((u < 0.f || v < 0.f || w < 0.f) && (u > 0.f || v > 0.f || w > 0.f)) return std::nullopt;
    const float det = u + v + w;
    if (det == 0.f) return std::nullopt;
    // Step: scaled hit distance, then t against the open interval (tMin, tMax).
    const float az = r.sz * akz, bz = r.sz * bkz, cz = r.sz * ckz;
    const float t = (u * az + v * bz + w * cz) / det;
    if (!(t > tMin && t < tMax)) return std::nullopt;
    return TriangleHit{t, v / det, w / det};
}

void TriangleCluster::set(int slot, const vec3& p0, const vec3& p1, const vec3& p2) {
    for (int a = 0; a < 3; ++a) {
        v[0][a][slot] = p0[a];
        v[1][a][slot] = p1[a];
        v[2][a][slot] = p2[a];
    }
}

namespace {

// intersectTriangleWatertight's core for N lanes at once, after the ray's axis
// permutation and the translation to its origin (a, b, c: the vertices' k
// coordinates): shear, edge functions, determinant, then t in (tMin, tMax).
// Stores t and the barycentrics of all N lanes and returns the hit lanes'
// mask; stores nothing when it is 0.
template <int N>
RTLAB_SIMD_INLINE std::uint32_t shearedEdgeTest(
    const simd::vfloat<N>& akx, const simd::vfloat<N>& aky, const simd::vfloat<N>& akz, const simd::vfloat<N>& bkx,
    const simd::vfloat<N>& bky, const simd::vfloat<N>& bkz, const simd::vfloat<N>& ckx, const simd::vfloat<N>& cky,
    const simd::vfloat<N>& ckz, const simd::vfloat<N>& sx, const simd::vfloat<N>& sy, const simd::vfloat<N>& sz,
    const simd::vfloat<N>& tMin, const simd::vfloat<N>& tMax, float* tOut, float* b1Out, float* b2Out) {
    using V = simd::vfloat<N>;
    using VI = simd::vint<N>;
    // Step: shear, edge functions, determinant.
    const V ax = akx - sx * akz, ay = aky - sy * akz;
    const V bx = bkx - sx * bkz, by = bky - sy * bkz;
    const V cx = ckx - sx * ckz, cy = cky - sy * ckz;
    const V u = cx * by - cy * bx;
    const V v = ax * cy - ay * cx;
    const V w = bx * ay - by * ax;
    const V zero = simd::splat<N>(0.f);
    const V det = u + v + w;
    const VI inside =
        ~(((u < zero) | (v < zero) | (w < zero)) & ((u > zero) | (v > zero) | (w > zero))) & (det != zero);
    // Step: early-out on an empty mask, before any division.
    if (simd::signMask<N>(inside) == 0) return 0;
    const V az = sz * akz, bz = sz * bkz, cz = sz * ckz;
    const V t = (u * az + v * bz + w * cz) / det;
    const std::uint32_t hit = simd::signMask<N>(inside & (t > tMin) & (t < tMax));
    if (hit == 0) return 0;
    simd::storeu<N>(tOut, t);
    simd::storeu<N>(b1Out, v / det);
    simd::storeu<N>(b2Out, w / det);
    return hit;
}

// Lanes [first, first + N) of the packet against one triangle.
template <int N>
RTLAB_SIMD_INLINE std::uint32_t intersectPacketLanes(const WatertightRayPacket& p, int first, const TriangleCluster& c,
                                                     int slot, float* tOut, float* b1Out, float* b2Out) {
    using V = simd::vfloat<N>;
    using VI = simd::vint<N>;
    auto lanes = [&](const float* a) { return simd::loadu<N>(a + first); };
    auto mask = [&](const std::int32_t* a) { return *reinterpret_cast<const typename simd::Lanes<N>::vi*>(a + first); };
    // Step: each lane's permuted coordinates of the three vertices.
    const V ox = lanes(p.ox), oy = lanes(p.oy), oz = lanes(p.oz);
    const V sx = lanes(p.sx), sy = lanes(p.sy), sz = lanes(p.sz);
    V akx, aky, akz, bkx, bky, bkz, ckx, cky, ckz;
    if (p.uniform) {
        akx = simd::splat<N>(c.v[0][p.kx][slot]) - ox, aky = simd::splat<N>(c.v[0][p.ky][slot]) - oy;
        akz = simd::splat<N>(c.v[0][p.kz][slot]) - oz;
        bkx = simd::splat<N>(c.v[1][p.kx][slot]) - ox, bky = simd::splat<N>(c.v[1][p.ky][slot]) - oy;
        bkz = simd::splat<N>(c.v[1][p.kz][slot]) - oz;
        ckx = simd::splat<N>(c.v[2][p.kx][slot]) - ox, cky = simd::splat<N>(c.v[2][p.ky][slot]) - oy;
        ckz = simd::splat<N>(c.v[2][p.kz][slot]) - oz;
    } else {
        const VI xIs0 = mask(p.xIs0), xIs1 = mask(p.xIs1), yIs0 = mask(p.yIs0), yIs1 = mask(p.yIs1);
        const VI zIs0 = mask(p.zIs0), zIs1 = mask(p.zIs1);
        auto permuted = [&](int k, const VI& is0, const VI& is1) __attribute__((always_inline)) {
            return simd::select<N>(
                is0, simd::splat<N>(c.v[k][0][slot]),
                simd::select<N>(is1, simd::splat<N>(c.v[k][1][slot]), simd::splat<N>(c.v[k][2][slot])));
        };
        akx = permuted(0, xIs0, xIs1) - ox, aky = permuted(0, yIs0, yIs1) - oy, akz = permuted(0, zIs0, zIs1) - oz;
        bkx = permuted(1, xIs0, xIs1) - ox, bky = permuted(1, yIs0, yIs1) - oy, bkz = permuted(1, zIs0, zIs1) - oz;
        ckx = permuted(2, xIs0, xIs1) - ox, cky = permuted(2, yIs0, yIs1) - oy, ckz = permuted(2, zIs0, zIs1) - oz;
    }
    return shearedEdgeTest<N>(akx, aky, akz, bkx, bky, bkz, ckx, cky, ckz, sx, sy, sz, lanes(p.tMin), lanes(p.tMax),
                              tOut + first, b1Out + first, b2Out + first)
           << first;
}

// makeWatertightRay for lanes [first, first + N) of structure-of-arrays rays.
template <int N>
RTLAB_SIMD_INLINE void setPacketLanes(WatertightRayPacket& p, int first, const float* ox, const float* oy,
                                      const float* oz, const float* dx, const float* dy, const float* dz) {
    using V = simd::vfloat<N>;
    using VI = simd::vint<N>;
    auto lanes = [&](const float* a) { return simd::loadu<N>(a + first); };
    auto store = [&](std::int32_t* a, const VI& v) { *reinterpret_cast<typename simd::Lanes<N>::vi*>(a + first) = v; };
    const V x = lanes(dx), y = lanes(dy), z = lanes(dz);
    const V zero = simd::splat<N>(0.f);
    const V ax = simd::select<N>(x < zero, -x, x), ay = simd::select<N>(y < zero, -y, y),
            az = simd::select<N>(z < zero, -z, z);
    // Step: the dominant axis kz (ties keep the lower axis, as makeWatertightRay).
    const VI zIs1Before = ay > ax;
    const VI zIs2 = az > simd::select<N>(zIs1Before, ay, ax);
    const VI zIs1 = zIs1Before & ~zIs2, zIs0 = ~zIs1Before & ~zIs2;
    const V dkz = simd::select<N>(zIs2, z, simd::select<N>(zIs1, y, x));
    const VI valid = simd::select<N>(dkz < zero, -dkz, dkz) > zero;
    // Step: kx = kz + 1, ky = kz + 2 (mod 3), swapped when d[kz] < 0.
    const VI neg = dkz < zero;
    const VI xIs0 = (neg & zIs1) | (~neg & zIs2), xIs1 = (neg & zIs2) | (~neg & zIs0);
    const VI yIs0 = (neg & zIs2) | (~neg & zIs1), yIs1 = (neg & zIs0) | (~neg & zIs2);
    auto pick = [&](const VI& is0, const VI& is1, const V& a0, const V& a1, const V& a2) {
        return simd::select<N>(is0, a0, simd::select<N>(is1, a1, a2));
    };
    const V dkx = pick(xIs0, xIs1, x, y, z), dky = pick(yIs0, yIs1, x, y, z);
    const V px = lanes(ox), py = lanes(oy), pz = lanes(oz);
    const V one = simd::splat<N>(1.f);
    const V safe = simd::select<N>(valid, dkz, one);  // no division by zero in invalid lanes
    auto keep = [&](const V& v) { return simd::select<N>(valid, v, zero); };
    store(p.xIs0, xIs0 & valid);
    store(p.xIs1, xIs1 & valid);
    store(p.yIs0, yIs0 & valid);
    store(p.yIs1, yIs1 & valid);
    store(p.zIs0, zIs0 & valid);
    store(p.zIs1, zIs1 & valid);
    store(p.permutation, (xIs0 & 1) | (xIs1 & 2) | (yIs0 & 4) | (yIs1 & 8) | (zIs0 & 16) | (zIs1 & 32));
    simd::storeu<N>(p.tMin + first, zero);
    simd::storeu<N>(p.tMax + first, zero);
    simd::storeu<N>(p.ox + first, keep(pick(xIs0, xIs1, px, py, pz)));
    simd::storeu<N>(p.oy + first, keep(pick(yIs0, yIs1, px, py, pz)));
    simd::storeu<N>(p.oz + first, keep(pick(zIs0, zIs1, px, py, pz)));
    simd::storeu<N>(p.sx + first, keep(dkx / safe));
    simd::storeu<N>(p.sy + first, keep(dky / safe));
    simd::storeu<N>(p.sz + first, keep(one / safe));
    p.validRays = (p.validRays & ~(((1u << N) - 1u) << first)) | (simd::signMask<N>(valid) << first);
}

__attribute__((target("avx2"))) void setPacketAvx2(WatertightRayPacket& p, const float* ox, const float* oy,
                                                   const float* oz, const float* dx, const float* dy, const float* dz) {
    setPacketLanes<8>(p, 0, ox, oy, oz, dx, dy, dz);
}

// Every slot of the cluster against the packet, N lanes per step.
template <int N>
RTLAB_SIMD_INLINE bool intersectPacketSlots(const WatertightRayPacket& p, const TriangleCluster& c, PacketHits& out) {
    std::uint32_t any = 0;
    for (int slot = 0; slot < static_cast<int>(c.count); ++slot) {
        std::uint32_t hit = 0;
        for (int first = 0; first < WatertightRayPacket::kLanes; first += N)
            if ((p.activeMask >> first) & ((1u << N) - 1u))
                hit |= intersectPacketLanes<N>(p, first, c, slot, out.t[slot], out.b1[slot], out.b2[slot]);
        out.mask[slot] = hit & p.activeMask;
        any |= out.mask[slot];
    }
    return any != 0;
}

__attribute__((target("avx2"))) bool intersectPacketAvx2(const WatertightRayPacket& p, const TriangleCluster& c,
                                                         PacketHits& out) {
    return intersectPacketSlots<8>(p, c, out);
}

}  // namespace

bool WatertightRayPacket::sharePermutation(std::uint32_t lanes) {
    WatertightRayPacket& p = *this;
    // Step: the permutation of the first lane, then whether all share it.
    const int first = std::countr_zero(lanes);
    const std::int32_t c = p.permutation[first];
    using VI = simd::vint<4>;
    const VI cs = {c, c, c, c};
    const VI* perm = reinterpret_cast<const VI*>(p.permutation);
    const std::uint32_t differs = simd::signMask<4>(perm[0] != cs) | (simd::signMask<4>(perm[1] != cs) << 4);
    if ((differs & lanes) != 0) return false;
    p.kx = p.xIs0[first] ? 0 : p.xIs1[first] ? 1 : 2;
    p.ky = p.yIs0[first] ? 0 : p.yIs1[first] ? 1 : 2;
    p.kz = p.zIs0[first] ? 0 : p.zIs1[first] ? 1 : 2;
    return true;
}

void WatertightRayPacket::setRays(const float* ox, const float* oy, const float* oz, const float* dx, const float* dy,
                                  const float* dz) {
    static const bool avx2 = simd::hasAvx2();
    if (avx2) {
        setPacketAvx2(*this, ox, oy, oz, dx, dy, dz);
    } else {
        setPacketLanes<4>(*this, 0, ox, oy, oz, dx, dy, dz);
        setPacketLanes<4>(*this, 4, ox, oy, oz, dx, dy, dz);
    }
    uniformValid = validRays != 0 && sharePermutation(validRays);
}

bool intersectPacketWatertight(const WatertightRayPacket& rays, const TriangleCluster& cluster, PacketHits& out) {
    static const bool avx2 = simd::hasAvx2();
    return avx2 ? intersectPacketAvx2(rays, cluster, out) : intersectPacketSlots<4>(rays, cluster, out);
}

void intersectClusterWatertight(const WatertightRay& r, const TriangleCluster& c, float tMin, float tMax,
                                ClusterHits& out) {
    out.mask = 0;
    if (!r.valid) return;
    // Every slot in one SIMD step: intersectTriangleWatertight lane by lane.
    constexpr int N = kClusterTriangles;
    using V = simd::vfloat<N>;
    const V okx = simd::splat<N>(r.ox), oky = simd::splat<N>(r.oy), okz = simd::splat<N>(r.oz);
    const V sx = simd::splat<N>(r.sx), sy = simd::splat<N>(r.sy), sz = simd::splat<N>(r.sz);
    auto coordinate = [&](int k, int axis) { return simd::loadu<N>(c.v[k][axis]); };
    const V akx = coordinate(0, r.kx) - okx, aky = coordinate(0, r.ky) - oky, akz = coordinate(0, r.kz) - okz;
    const V bkx = coordinate(1, r.kx) - okx, bky = coordinate(1, r.ky) - oky, bkz = coordinate(1, r.kz) - okz;
    const V ckx = coordinate(2, r.kx) - okx, cky = coordinate(2, r.ky) - oky, ckz = coordinate(2, r.kz) - okz;
    out.mask = shearedEdgeTest<N>(akx, aky, akz, bkx, bky, bkz, ckx, cky, ckz, sx, sy, sz, simd::splat<N>(tMin),
                                  simd::splat<N>(tMax), out.t, out.b1, out.b2);
}

}  // namespace rtlab::tracer
