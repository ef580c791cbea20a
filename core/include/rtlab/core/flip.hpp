#pragma once
// FLIP, a perceptual image-difference metric for "flipping" between a test
// image and a reference image:
//
//  - LDR-FLIP: Andersson, Nilsson, Akenine-Möller, Oskarsson, Åström,
//    Fairchild, "FLIP: A Difference Evaluator for Alternating Images",
//    Proc. ACM Comput. Graph. Interact. Tech. 3(2) (HPG 2020).
//  - HDR-FLIP: Andersson, Nilsson, Shirley, Akenine-Möller, "Visualizing
//    Errors in Rendered High Dynamic Range Images", Eurographics 2021 short
//    paper: the LDR-FLIP maximum over a range of exposures of ACES
//    tone-mapped images, the range derived from the reference.
//
// The per-pixel error lies in [0, 1] (0 = no perceived difference). The
// results are deterministic and independent of the thread count: every pixel
// is computed from its neighbourhood only, and reductions run in pixel order.
#include <rtlab/core/image.hpp>
#include <rtlab/core/math.hpp>

#include <vector>

namespace rtlab {

struct FlipOptions {
    // Pixels per degree of visual angle of the observer. The FLIP paper's
    // default viewing condition: a 0.7 m wide 3840-pixel monitor seen from
    // 0.7 m, i.e. 0.7 * (3840 / 0.7) * pi / 180 = 67.0206 ppd ("about 67").
    // Must be in (0, 1e5]; filter widths (and the cost) grow linearly with it.
    double pixelsPerDegree = 0.7 * (3840.0 / 0.7) * 3.14159265358979323846 / 180.0;
};

struct FlipResult {
    std::vector<float> errorMap;  // one error in [0, 1] per pixel, row-major, top row first
    int width = 0;
    int height = 0;
    double mean = 0.0;      // mean of errorMap: the paper's single-number FLIP
    double median = 0.0;    // median of errorMap (mean of the two middle values for an even count)
    double maxError = 0.0;  // largest value in errorMap

    // HDR-FLIP only (0 for LDR-FLIP): the exposure range in stops and the
    // number of exposures whose LDR-FLIP maps were combined by a per-pixel max.
    double startExposure = 0.0;
    double stopExposure = 0.0;
    int exposureCount = 0;
};

// LDR-FLIP of two display images, sRGB-encoded, each channel in [0, 1] (not
// linear RGB). Sanitising: NaN becomes 0, everything else is clamped to
// [0, 1] (so +inf -> 1, -inf and negatives -> 0); the error map is never NaN.
// Throws std::invalid_argument when width or height is not positive, when
// either image does not have width * height pixels, or when pixelsPerDegree is
// out of range. Filters clamp at the borders, so any size from 1x1 up works.
FlipResult ldrFlip(const std::vector<vec3>& testSrgb, const std::vector<vec3>& referenceSrgb, int width, int height,
                   const FlipOptions& options = {});

// HDR-FLIP of two linear-radiance images (linear Rec.709/sRGB primaries).
// Exposures are spread evenly, at most one stop apart and at least two of
// them, from the start exposure log2(x85 / Ymax) to the stop exposure
// log2(x85 / Ymedian), with Y the reference's luminance and x85 the ACES input
// that tone-maps to 0.85; each exposure is ACES tone-mapped, clamped to
// [0, 1], compared with LDR-FLIP (as linear RGB), and the per-pixel maximum is
// kept. Sanitising: NaN becomes 0 and values are clamped to [0, 65536] (so
// negatives -> 0, +inf -> 65536). Where the paper's range is undefined:
// a median luminance of 0 is replaced by the median of the positive
// luminances, and a reference without any positive luminance uses exposure 0.
// The cost is one LDR-FLIP per exposure, about log2(Ymax / Ymedian) of them.
// Throws std::invalid_argument like ldrFlip.
FlipResult hdrFlip(const std::vector<vec3>& testLinear, const std::vector<vec3>& referenceLinear, int width, int height,
                   const FlipOptions& options = {});

// The error map through the "magma" colour map the paper shows FLIP maps with
// (matplotlib's magma, 256 entries, index round(255 * error)), as an Image
// with "R", "G", "B" channels in linear RGB: writePng's sRGB encoding gives
// back magma's display colours. Errors outside [0, 1] are clamped, NaN -> 0.
Image flipErrorImage(const FlipResult& result);

}  // namespace rtlab
