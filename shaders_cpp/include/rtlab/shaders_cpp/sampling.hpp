#pragma once
// Sampling and geometry toolkit for the effect shaders (shadows, reflections,
// AO, GI, DDGI), pbrt-v4 style: free functions, deterministic, and free of
// NaN/Inf for every finite input, including degenerate ones (zero vectors,
// grazing angles, u = 1, roughness 0). Local shading space is z-up: the
// normal is (0,0,1), cos(theta) = v.z.
//
// References
//   Duff et al. 2017, "Building an Orthonormal Basis, Revisited", JCGT 6(1).
//   Heitz 2018, "Sampling the GGX Distribution of Visible Normals", JCGT 7(4).
//   Heitz 2014, "Understanding the Masking-Shadowing Function in
//     Microfacet-Based BRDFs", JCGT 3(2) (height-correlated Smith G2).
//   Karis 2013, "Real Shading in Unreal Engine 4" (split-sum specular).
//   Waechter & Binder 2019, "A Fast and Robust Method for Avoiding
//     Self-Intersection", Ray Tracing Gems ch. 6.
//   Keinert et al. 2015, "Spherical Fibonacci Mapping", SIGGRAPH Asia.
//   Cigolle et al. 2014, "A Survey of Efficient Representations for
//     Independent Unit Vectors", JCGT 3(2) (octahedral mapping).
//   Majercik et al. 2019, "Dynamic Diffuse Global Illumination with
//     Ray-Traced Irradiance Fields", JCGT 8(2) (probe tiles and borders).
#include <rtlab/core/math.hpp>

#include <cstddef>
#include <cstdint>
#include <span>

namespace rtlab::shaders {

// Largest float below 1: every sampler clamps u into [0, kOneMinusEpsilon]
// (NaN -> 0), so u = 1 is a legal input.
inline constexpr float kOneMinusEpsilon = 0x1.fffffep-1f;

// ---------------------------------------------------------------- frames --

// Right-handed orthonormal basis with n as z: cross(t, b) == n.
struct Frame {
    vec3 t{1.f, 0.f, 0.f};
    vec3 b{0.f, 1.f, 0.f};
    vec3 n{0.f, 0.f, 1.f};
};

// Branch-free (except the sign) basis of Duff et al. 2017; n is normalized
// first, a zero or non-finite n gives the z-up frame.
Frame makeFrame(vec3 n);
vec3 toLocal(const Frame& f, vec3 v);
vec3 toWorld(const Frame& f, vec3 v);

// -------------------------------------------------------------- sampling --

// Cosine-weighted hemisphere (local, z up) via the concentric disk mapping;
// pdf = max(cos theta, 0) / pi, per solid angle.
vec3 sampleCosineHemisphere(vec2 u);
float cosineHemispherePdf(float cosTheta);

vec3 sampleUniformSphere(vec2 u);
float uniformSpherePdf();  // 1 / (4 pi)

// Uniform in the cone of directions with cos(theta) >= cosThetaMax around +z.
// cosThetaMax is clamped to [-1, 1]; the pdf stays finite (capped at 1e30)
// as the cone collapses to a direction.
vec3 sampleUniformCone(vec2 u, float cosThetaMax);
float uniformConePdf(float cosThetaMax);

// ----------------------------------------------------------------- GGX --
//
// Trowbridge-Reitz (GGX), isotropic, alpha = roughness^2. Every function
// clamps alpha into [kMinGgxAlpha, 1] (NaN -> kMinGgxAlpha). The value
// 1e-7 is the largest alpha for which *every* sample u in [0, 1 - 2^-24]^2
// reflects within 1e-3 rad of the mirror direction (max tan(theta_h) =
// alpha / sqrt(2^-24) = 4.1e-4): GGX's long tail puts ~4% of the samples
// more than 1e-3 away at alpha = 1e-4. The peak D = 1/(pi alpha^2) = 3.2e13
// is still far from float overflow. Directions are in the local frame; the
// Smith terms use |cos|, so callers reject below-surface directions.
inline constexpr float kMinGgxAlpha = 1e-7f;

// alpha = clamp(roughness, 0, 1)^2, at least kMinGgxAlpha.
float ggxAlpha(float roughness);

// Normal distribution D(h); h need not be unit. Integrates to 1 against
// cos(theta_h) over the upper hemisphere; even in h.z (like pbrt-v4), so the
// caller (or the visible-normal pdf) restricts h to the relevant side.
float ggxD(vec3 h, float alpha);
// Smith masking G1(v) = 1 / (1 + Lambda(v)) (scale invariant in v).
float ggxG1(vec3 v, float alpha);
// Height-correlated masking-shadowing G2 = 1 / (1 + Lambda(wo) + Lambda(wi)).
float ggxG2(vec3 wo, vec3 wi, float alpha);

// Visible normal sampling (Heitz 2018): h ~ G1(wo) max(0, wo.h) D(h) / |wo.z|.
// wo below the surface (wo.z < 0) is handled as its mirror image, so the
// returned unit h is always on wo's side: dot(h, wo) >= 0.
vec3 sampleGgxVisibleNormal(vec3 wo, float alpha, vec2 u);
// 0 unless h is on wo's side of the surface and dot(wo, h) > 0.
float ggxVisibleNormalPdf(vec3 wo, vec3 h, float alpha);

// Mirror wo about h: 2 (wo.h) h - wo.
vec3 reflectAbout(vec3 wo, vec3 h);

struct GgxReflectionSample {
    vec3 wi{0.f, 0.f, 1.f};  // reflected direction (unit)
    vec3 h{0.f, 0.f, 1.f};   // sampled visible normal
    float pdf = 0.f;         // per solid angle of wi; 0 = wi left wo's hemisphere, discard
};
// Samples h with sampleGgxVisibleNormal and reflects wo about it;
// pdf = pdf_vndf(h) / (4 |wo.h|) = G1(wo) D(h) / (4 |wo.z|).
GgxReflectionSample sampleGgxReflection(vec3 wo, float alpha, vec2 u);
// The same pdf for a given pair (h = normalize(wo + wi)); 0 when wo and wi
// are not in the same hemisphere.
float ggxReflectionPdf(vec3 wo, vec3 wi, float alpha);

// Schlick's Fresnel: f0 + (1 - f0) (1 - cos)^5, cos clamped to [0, 1].
float fresnelSchlick(float f0, float cosTheta);
vec3 fresnelSchlick(vec3 f0, float cosTheta);

// Pre-integrated (split-sum) specular term: directional albedo of
// GGX + height-correlated Smith + Schlick at (NdotV, roughness) equals
// f0 * x + y. Bilinear lookup into a 32x32 table over NdotV, roughness in
// [0, 1] (nodes at i/31), built once on first use (thread-safe, deterministic)
// with 1024 Hammersley VNDF samples per node. Inputs are clamped to [0, 1];
// x, y, x + y are in [0, 1].
vec2 specularBrdfIntegral(float NdotV, float roughness);

// -------------------------------------------------------------- geometry --

// Waechter & Binder self-intersection offset: moves p a few ULPs along ng
// (normalized here; pass the normal on the side the ray leaves from).
// Components with |p| < 1/32 get a float offset of ng/65536 instead.
// Finite p gives a finite result (clamped at +-FLT_MAX); a zero ng returns p.
vec3 offsetRayOrigin(vec3 p, vec3 ng);

// The offset the renderer uses: the same idea (move the hit point off its
// surface by a few units in the last place along the geometric normal), but
// measured in ulps of `errorMagnitude`, the largest |coordinate| that went
// into computing p (the ray origin's and p's own): 8 ulps of it, at least one
// ulp of each moved component. W&B's fixed 256-ulp offset is ~2^-15 of the
// coordinates (3 units at 1e5: through the walls of a 2-unit room), and its
// 1/65536 floor near the origin is larger than a whole scene scaled by 1e-4;
// both break the far/tiny scene tests this one passes. ng is normalized
// here; zero or non-finite input returns p.
vec3 offsetRayOriginByError(vec3 p, vec3 ng, float errorMagnitude);

// Point i (taken modulo n) of n spherical Fibonacci points: unit vectors,
// evenly spread, z from 1 - 1/n down to -1 + 1/n. n = 0 gives +z.
vec3 sphericalFibonacci(std::uint32_t i, std::uint32_t n);
// The same point rotated (e.g. DDGI's per-frame random rotation).
vec3 sphericalFibonacci(std::uint32_t i, std::uint32_t n, const mat3& rotation);
// Uniformly distributed random rotation from three uniforms (Shoemake 1992,
// via a unit quaternion); a proper orthonormal matrix.
mat3 randomRotation(vec3 u);

// Octahedral map: unit direction -> [-1, 1]^2 (the -z hemisphere folded onto
// the corners), and back (the result is unit). A zero vector encodes to (0,0);
// decode clamps its input into [-1, 1]^2.
vec2 octEncode(vec3 dir);
vec3 octDecode(vec2 e);

// DDGI probe tiles (Majercik et al. 2019): an N x N octahedral interior with a
// one-texel border, (N+2) x (N+2) texels row-major, tile texel (x, y) at index
// y * (N+2) + x, interior texel (i, j) at tile texel (i+1, j+1). Texel row j
// covers oct v in [-1 + 2j/N, -1 + 2(j+1)/N].
std::size_t ddgiTileIndex(int x, int y, int interiorSize);
// Direction through the centre of interior texel (i, j), 0 <= i, j < N.
vec3 ddgiTexelDirection(int i, int j, int interiorSize);
// Continuous tile coordinate of a direction: texel (x, y) spans [x, x+1) x
// [y, y+1); the result lies in [1, N+1]^2, so bilinear taps stay inside the tile.
vec2 ddgiTileCoord(vec3 dir, int interiorSize);
// Fills the border from the interior by the octahedral wrap rule: edge texels
// copy the adjacent interior row/column mirrored, corners copy the diagonally
// opposite interior corner. Throws std::invalid_argument unless
// tile.size() == (N+2)^2 and N >= 1.
void ddgiFillTileBorder(std::span<vec3> tile, int interiorSize);
void ddgiFillTileBorder(std::span<vec2> tile, int interiorSize);

// ---------------------------------------------------------------- misc --

// Veach's power heuristic (beta = 2) weight of strategy f; robust to huge,
// zero and infinite pdfs (0 if f's pdf is 0, never NaN).
float powerHeuristic(int nf, float fPdf, int ng, float gPdf);

// Rec. 709 luminance.
float luminance(vec3 rgb);

}  // namespace rtlab::shaders
