#include <rtlab/tracer/watertight_triangle.hpp>

#include <cmath>
#include <utility>

namespace rtlab::tracer {

std::optional<TriangleHit> intersectTriangleWatertight(const vec3& origin, const vec3& direction, const vec3& p0,
                                                       const vec3& p1, const vec3& p2, float tMin, float tMax) {
    const glm::dvec3 d(direction);
    // Step: permute so that z is the dominant direction axis; swapping x and y
    // when d.z < 0 keeps the winding.
    int kz = 0;
    if (std::abs(d.y) > std::abs(d[kz])) kz = 1;
    if (std::abs(d.z) > std::abs(d[kz])) kz = 2;
    if (d[kz] == 0.0) return std::nullopt;
    int kx = (kz + 1) % 3, ky = (kx + 1) % 3;
    if (d[kz] < 0.0) std::swap(kx, ky);
    // Step: shear so the ray runs along +z from the origin.
    const double sx = d[kx] / d[kz], sy = d[ky] / d[kz], sz = 1.0 / d[kz];
    const glm::dvec3 o(origin);
    const glm::dvec3 a = glm::dvec3(p0) - o, b = glm::dvec3(p1) - o, c = glm::dvec3(p2) - o;
    const double ax = a[kx] - sx * a[kz], ay = a[ky] - sy * a[kz];
    const double bx = b[kx] - sx * b[kz], by = b[ky] - sy * b[kz];
    const double cx = c[kx] - sx * c[kz], cy = c[ky] - sy * c[kz];
    // Step: edge functions; the same edge in two triangles gives exactly negated values.
    const double u = cx * by - cy * bx;
    const double v = ax * cy - ay * cx;
    const double w = bx * ay - by * ax;
    if ((u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0)) return std::nullopt;
    const double det = u + v + w;
    if (det == 0.0) return std::nullopt;
    // Step: scaled hit distance against the open interval (tMin, tMax).
    const double t = (u * sz * a[kz] + v * sz * b[kz] + w * sz * c[kz]) / det;
    if (!(t > double(tMin) && t < double(tMax))) return std::nullopt;
    const float tf = static_cast<float>(t);
    if (!(tf > tMin && tf < tMax)) return std::nullopt;  // rounding to float must keep it inside
    return TriangleHit{tf, static_cast<float>(v / det), static_cast<float>(w / det)};
}

}  // namespace rtlab::tracer
