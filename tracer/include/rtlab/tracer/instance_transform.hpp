#pragma once
// The instance-transform step every traversal back end shares: a world ray
// enters an instance's object space through objectFromWorld = inverse of
// worldFromObject, computed and applied in double precision and rounded once
// to float, so that the object-space ray is (nearly) the correctly rounded
// image of the world ray. Embree's watertight-triangle callback and the
// RT-core model both use it, which makes their triangle tests see the same
// inputs and give bit-identical t and barycentrics. The direction is not
// normalised, so t means the same distance parameter in both spaces.
#include <rtlab/core/math.hpp>

namespace rtlab::tracer {

inline glm::dmat4 objectFromWorldOf(const mat4& worldFromObject) { return glm::inverse(glm::dmat4(worldFromObject)); }

struct ObjectSpaceRay {
    vec3 origin{0.f};
    vec3 direction{0.f};
};

// The two halves of the transform, written out (x, y, z only) so that a
// caller may transform a shared origin once for many directions; the
// results are the same bits as toObjectSpace's.
inline vec3 objectSpacePoint(const glm::dmat4& m, const vec3& p) {
    const double x = p.x, y = p.y, z = p.z;
    return vec3(static_cast<float>(((m[0][0] * x + m[1][0] * y) + m[2][0] * z) + m[3][0]),
                static_cast<float>(((m[0][1] * x + m[1][1] * y) + m[2][1] * z) + m[3][1]),
                static_cast<float>(((m[0][2] * x + m[1][2] * y) + m[2][2] * z) + m[3][2]));
}
inline vec3 objectSpaceVector(const glm::dmat4& m, const vec3& v) {
    const double x = v.x, y = v.y, z = v.z;
    return vec3(static_cast<float>((m[0][0] * x + m[1][0] * y) + m[2][0] * z),
                static_cast<float>((m[0][1] * x + m[1][1] * y) + m[2][1] * z),
                static_cast<float>((m[0][2] * x + m[1][2] * y) + m[2][2] * z));
}

// Eight rays at once, structure of arrays ([axis][lane]): lane by lane the
// same bits as objectSpacePoint / objectSpaceVector (lane-wise double
// arithmetic in the same order, rounded once to float; AVX2 when the CPU has
// it). The traversal contexts set up a packet's object rays per instance with it.
void objectSpaceRays8(const glm::dmat4& objectFromWorld, const float (&worldOrigin)[3][8],
                      const float (&worldDirection)[3][8], float (&objectOrigin)[3][8], float (&objectDirection)[3][8]);

inline ObjectSpaceRay toObjectSpace(const glm::dmat4& objectFromWorld, const vec3& worldOrigin,
                                    const vec3& worldDirection) {
    return {objectSpacePoint(objectFromWorld, worldOrigin), objectSpaceVector(objectFromWorld, worldDirection)};
}

}  // namespace rtlab::tracer
