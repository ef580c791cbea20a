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

inline ObjectSpaceRay toObjectSpace(const glm::dmat4& objectFromWorld, const vec3& worldOrigin,
                                    const vec3& worldDirection) {
    return {vec3(objectFromWorld * glm::dvec4(glm::dvec3(worldOrigin), 1.0)),
            vec3(glm::dmat3(objectFromWorld) * glm::dvec3(worldDirection))};
}

}  // namespace rtlab::tracer
