#include <rtlab/core/simd.hpp>
#include <rtlab/tracer/instance_transform.hpp>

namespace rtlab::tracer {
namespace {

template <int W>
struct DoubleLanes {
    typedef double vd __attribute__((vector_size(W * sizeof(double))));
    typedef float vf __attribute__((vector_size(W * sizeof(float))));
};

// W lanes per step in double vectors (W = 2: SSE2, W = 4: AVX2). Every lane
// runs exactly the scalar objectSpacePoint/objectSpaceVector operations.
template <int W>
RTLAB_SIMD_INLINE void transformLanes(const glm::dmat4& m, const float (&wo)[3][8], const float (&wd)[3][8],
                                      float (&oo)[3][8], float (&od)[3][8]) {
    using vd = typename DoubleLanes<W>::vd;
    using vf = typename DoubleLanes<W>::vf;
    auto load = [](const float* p) {
        vf v;
        __builtin_memcpy(&v, p, sizeof v);
        return __builtin_convertvector(v, vd);
    };
    auto store = [](float* p, const vd& v) {
        const vf f = __builtin_convertvector(v, vf);
        __builtin_memcpy(p, &f, sizeof f);
    };
    auto splat = [](double x) {
        vd v;
        for (int i = 0; i < W; ++i) v[i] = x;
        return v;
    };
    for (int first = 0; first < 8; first += W) {
        const vd px = load(&wo[0][first]), py = load(&wo[1][first]), pz = load(&wo[2][first]);
        const vd vx = load(&wd[0][first]), vy = load(&wd[1][first]), vz = load(&wd[2][first]);
        for (int r = 0; r < 3; ++r) {
            const vd m0 = splat(m[0][r]), m1 = splat(m[1][r]), m2 = splat(m[2][r]);
            store(&oo[r][first], ((m0 * px + m1 * py) + m2 * pz) + splat(m[3][r]));
            store(&od[r][first], (m0 * vx + m1 * vy) + m2 * vz);
        }
    }
}

__attribute__((target("avx2"))) void transformAvx2(const glm::dmat4& m, const float (&wo)[3][8],
                                                   const float (&wd)[3][8], float (&oo)[3][8], float (&od)[3][8]) {
    transformLanes<4>(m, wo, wd, oo, od);
}

}  // namespace

void objectSpaceRays8(const glm::dmat4& objectFromWorld, const float (&worldOrigin)[3][8],
                      const float (&worldDirection)[3][8], float (&objectOrigin)[3][8],
                      float (&objectDirection)[3][8]) {
    static const bool avx2 = simd::hasAvx2();
    if (avx2) transformAvx2(objectFromWorld, worldOrigin, worldDirection, objectOrigin, objectDirection);
    else transformLanes<2>(objectFromWorld, worldOrigin, worldDirection, objectOrigin, objectDirection);
}

}  // namespace rtlab::tracer
