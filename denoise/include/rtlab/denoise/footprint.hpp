#pragma once
// Kernel footprints of the per-effect stacks: how far (in pixels) the
// a-trous filter may reach from each pixel (atrousFilter's footprintPx),
// derived from what the effect's pass measured. All inputs are images: the
// G-buffer's per-pixel world width of a pixel (footprint.pixelWorld) and the
// effect's own buffers. Outputs are >= 0 and finite for any input.
#include <rtlab/denoise/common.hpp>

#include <span>
#include <vector>

namespace rtlab::denoise {

struct FootprintParams {
    // Largest footprint in pixels (the 5-iteration kernel reaches 62). Source: rtlab.
    float maxPx = 64.f;
    // Smallest footprint where the signal is noisy at all (2 = one a-trous
    // iteration, the 5x5 kernel). Source: rtlab.
    float minPx = 2.f;
    // The footprint map is averaged over (2 smoothRadius + 1)^2 geometry
    // pixels, so that a 1-spp distance estimate does not flip the number of
    // iterations from pixel to pixel. Source: rtlab.
    int smoothRadius = 2;
    // Every geometry pixel's footprint is at least this (0: a footprint may
    // be 0, no spatial filter). For signals whose noise does not come from
    // the quantity the footprint follows: a mirror's reflection is sharp,
    // but the light sampled at the reflected surface is noisy. Source: rtlab.
    float floorPx = 0.f;
    // Reflections only: pixels with roughness below this keep their own lobe
    // footprint - not smoothed with their neighbours', no floorPx, 0 below
    // minPx - so a mirror or near-mirror is not blurred beyond what its lobe
    // and hit distance allow (the footprint goes to 0 as roughness -> 0);
    // its noise is left to the temporal history. 0 = off. Source: rtlab.
    float sharpBelowRoughness = 0.f;
    // Reflections only: where the reflected hit distances of the pixel's
    // (2 smoothRadius + 1)^2 window (same mesh; a miss counts as 1e4) span
    // more than this ratio, the window sees an edge of the reflected image
    // (the floor's reflection of a box's side against the far wall), which
    // the surface's own depth and normal do not show: the footprint is
    // capped at edgeCapPx there, so the a-trous taps do not carry one side
    // of the reflected edge onto the other. 0 = off. Source: rtlab.
    float edgeHitRatio = 0.f;
    float edgeCapPx = 2.f;
};

// The pixel's width on the surface, from its width across the ray
// (footprint.pixelWorld) and the screen-space depth gradient (depth units
// per pixel, GuideBuffers::depthGrad): a surface at angle theta to the view
// stretches the pixel to pixelWorld / cos theta along its slope, with
// tan theta ~ |grad depth| / pixelWorld; the isotropic filter takes the
// ellipse's area-equivalent width, pixelWorld / sqrt(cos theta). Without
// it a grazing wall's footprints (penumbra, lobe or occluder distance over
// pixelWorld) were up to 1 / cos theta too wide in pixels. Capped at 100x
// pixelWorld (theta within 0.6 degrees of grazing); non-positive or
// non-finite pixelWorld passes through, a non-finite gradient counts as 0.
std::vector<float> surfacePixelWorld(std::span<const float> pixelWorld, std::span<const vec2> depthGrad);

// Shadows: the PCSS penumbra width (world units, the shadow pass's
// shadow.light<i>.penumbra; 0 where no occluder was seen) over the pixel's
// world width. Pixels with no estimate take the largest estimate within
// `searchRadius` pixels (PCSS's blocker search, in screen space; none: 0 =
// unoccluded, nothing to filter). Then smoothed and clamped to
// [minPx, maxPx] (0 stays 0).
std::vector<float> shadowFootprint(int width, int height, std::span<const float> penumbraWorld,
                                   std::span<const float> pixelWorld, std::span<const int> meshId,
                                   const FootprintParams& params = {}, int searchRadius = 8);

// Reflections: the GGX lobe (alpha = roughness^2) widens to about
// lobeScale x alpha x hit distance at the reflected surface; over the
// pixel's world width. A mirror (roughness 0) gets 0: no spatial filter. A
// miss (hitT 0) counts as maxPx away (except below
// params.sharpBelowRoughness, where a miss of a mirror reflects the sky
// sharply: 0). Source of lobeScale (2): rtlab, the
// lobe's half-width at half maximum is about alpha radians.
std::vector<float> reflectionFootprint(int width, int height, std::span<const float> roughness,
                                       std::span<const float> hitT, std::span<const float> pixelWorld,
                                       std::span<const int> meshId, const FootprintParams& params = {},
                                       float lobeScale = 2.f);

// Ambient occlusion: the mean occluder distance (ao.hitT; the AO radius
// where nothing was hit) over the pixel's world width: small in contact
// regions, wide in the open (Jimenez et al. 2016 use the same scale). The
// window mean takes only the pixels that saw an occluder (visibility ao.V
// below 1): an unoccluded 1-spp sample in a crease says nothing about its
// scale. A window without any takes all its pixels (the AO radius).
std::vector<float> aoFootprint(int width, int height, std::span<const float> hitT, std::span<const float> visibility,
                               std::span<const float> pixelWorld, std::span<const int> meshId,
                               const FootprintParams& params = {});

}  // namespace rtlab::denoise
