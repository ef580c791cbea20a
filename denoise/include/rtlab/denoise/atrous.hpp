#pragma once
// Edge-avoiding a-trous wavelet filter guided by variance (SVGF, Schied et
// al. 2017, section 4.3; Dammertz et al. 2010).
#include <rtlab/denoise/guides.hpp>

#include <memory>
#include <span>

namespace rtlab::denoise {

struct AtrousParams {
    // Number of iterations; iteration i uses step 2^i. Source: paper (5);
    // Falcor's SVGFPass default is 4.
    int iterations = 5;
    // Depth edge-stopping: exp(-|z - z'| / (sigmaZ |grad z . (p - q)| + depthEpsilon * z)).
    // sigmaZ source: paper (1). Falcor uses |dz/dx|+|dz/dy| * step * |offset| instead
    // of the projected gradient, i.e. also 1.
    float sigmaZ = 1.f;
    // Depth edge-stopping against the centre's tangent plane: the numerator
    // is |z' - (z + grad z . (q - p))|, the tap's distance in depth from the
    // plane through the centre, instead of |z - z'|. On a plane seen at a
    // slope the paper's term is about 1 / sigmaZ for every tap along the
    // depth gradient and about 0 across it, so the kernel filters across
    // more than along (streaks across a receding floor); this one is about 0
    // in every direction and still large across a depth edge. Source: rtlab
    // (the plane distance of NRD's ReLAX / ReBLUR geometry weight, in
    // screen-space depth).
    bool depthFromPlane = false;
    // Normal edge-stopping: exp(-sigmaN (1 - n.n')) (normals scaled to unit
    // length), the first-order form of the paper's max(0, n.n')^sigmaN =
    // exp(sigmaN ln(n.n')): never below it; for sigmaN 128 within 0.4 % where
    // the power is >= 0.37, 2 % where >= 0.1, 9 % where >= 0.01; both are
    // < 1e-16 across a 45-degree edge. Source: paper and Falcor (128); the exponential form: rtlab (it
    // joins the depth and luminance terms in one exponent).
    float sigmaN = 128.f;
    // Luminance edge-stopping: exp(-|l - l'| / (sigmaL sqrt(g3x3(Var)) + luminanceEpsilon)).
    // Source: paper (4); Falcor's PhiColor default is 10.
    float sigmaL = 4.f;
    // The depth epsilon, relative to the centre depth (paper: "small epsilon").
    // Source: rtlab.
    float depthEpsilon = 1e-3f;
    // The luminance epsilon (paper: "small epsilon"). Source: rtlab, chosen to
    // equal Falcor's floor sigmaL * sqrt(1e-10) for sigmaL = 1.
    float luminanceEpsilon = 1e-5f;
};

// Scratch buffers of the filter, kept between calls by a caller that filters
// every frame (SvgfFilter): large fresh allocations cost page faults that
// were as expensive as the filtering itself.
class AtrousWorkspace {
public:
    AtrousWorkspace();
    ~AtrousWorkspace();
    AtrousWorkspace(AtrousWorkspace&&) noexcept;
    AtrousWorkspace& operator=(AtrousWorkspace&&) noexcept;
    struct Buffers;  // private to atrous.cpp
    std::unique_ptr<Buffers> buffers_;
};

// One a-trous iteration with the given step (1, 2, 4, ...): the 5x5 kernel
// h = (1/16, 1/4, 3/8, 1/4, 1/16) x h at offsets step * (-2..2), times the
// edge-stopping weights (centre weight 1; off-screen and, for a geometry
// centre, sky taps skipped; sky centres pass through unchanged):
//   colorOut    = sum h w c / sum h w
//   varianceOut = sum h^2 w^2 Var / (sum h w)^2
// Outputs must not alias inputs.
//
// `footprintPx` (optional, one value per pixel) limits how far the filter
// reaches from each pixel, for the per-effect stacks whose footprint follows
// the signal (penumbra width, glossy lobe, AO hit distance): an iteration
// with step s, whose kernel reaches 2s pixels, is applied to a pixel only
// where 2s <= footprintPx; elsewhere colour and variance pass through. So a
// footprint below 2 means no spatial filtering, 2..3 one iteration, 4..7 two,
// and so on. Empty = unlimited (plain SVGF).
//
// The edge-stopping weight is one exponential of the three terms' sum,
// exp(-(normal + depth + luminance term)) = 2^-E, evaluated as a float whose
// bits are (127 - E) 2^23 (Schraudolph 1999: 2^-floor(E) (1 - frac(E) / 2),
// within +6.2 % / -0 % of 2^-E, exactly 1 at E = 0; with the kernel weight
// h = m 2^-k (m 1 or 3/2) folded into the bits, exactly 0 from E = 127 - k
// on, k 4 to 8), so a sky tap (normal 0) or a tap in the planes' zero
// margins gets weight 0.
//
// Implementation: 8-wide AVX2 (picked at run time) or 4-wide SSE2 SIMD over
// consecutive pixels of a row (lane-wise IEEE arithmetic, no FMA, so results
// do not depend on the vector width or the thread count).
void atrousIteration(const GuideBuffers& guides, std::span<const vec3> color, std::span<const float> variance, int step,
                     const AtrousParams& params, std::span<vec3> colorOut, std::span<float> varianceOut,
                     std::span<const float> footprintPx = {});

// params.iterations iterations with steps 1, 2, 4, ... . When `tapColor` is not
// empty it receives the colour after min(tapIterations, iterations) iterations
// (0 = the input): SVGF's colour history ("feedback tap"). Outputs may not
// alias inputs; with 0 iterations the outputs are copies of the inputs.
void atrousFilter(const GuideBuffers& guides, std::span<const vec3> color, std::span<const float> variance,
                  const AtrousParams& params, std::span<vec3> colorOut, std::span<float> varianceOut,
                  int tapIterations = 0, std::span<vec3> tapColor = {}, std::span<const float> footprintPx = {},
                  AtrousWorkspace* workspace = nullptr);

}  // namespace rtlab::denoise
