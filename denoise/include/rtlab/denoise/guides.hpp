#pragma once
// Guide buffers (the "G-buffer" a denoiser may look at): per-pixel linear
// depth, world normal, mesh id and motion, plus the screen-space depth
// gradient derived from the depth. Plain arrays, no scene access.
#include <rtlab/denoise/common.hpp>

#include <cstddef>
#include <vector>

namespace rtlab::denoise {

struct GuideBuffers {
    int width = 0;
    int height = 0;
    // Linear view depth (distance along the view axis), > 0 on geometry.
    // Ignored on sky pixels (it may hold anything there, including +inf).
    std::vector<float> depth;
    // Unit world-space shading normal. Ignored on sky pixels.
    std::vector<vec3> normal;
    // Mesh (or instance) id of the primary hit; -1 = sky / miss.
    std::vector<int> meshId;
    // Screen-space motion in pixels, previous position minus current position:
    // the pixel centre (x + .5, y + .5) was at (x + .5, y + .5) + motion in the
    // previous frame.
    std::vector<vec2> motion;
    // Optional (dz/dx, dz/dy) per pixel, in depth units per pixel. When empty,
    // the stages that need it compute it with depthGradient().
    std::vector<vec2> depthGrad;

    GuideBuffers() = default;
    // All buffers sized for width x height: depth 1, normal +Z, mesh id 0,
    // motion 0, depthGrad empty.
    GuideBuffers(int width, int height);

    std::size_t pixelCount() const { return static_cast<std::size_t>(width) * static_cast<std::size_t>(height); }
    bool isSky(std::size_t i) const { return meshId[i] < 0; }
    // Throws std::invalid_argument when a buffer's size does not match
    // width x height (depthGrad may also be empty).
    void validate() const;
};

// Screen-space depth gradient (dz/dx, dz/dy) of every pixel. Per axis it takes
// the one-sided difference (forward or backward) of smaller magnitude among the
// neighbours that are on screen and carry the same mesh id, so a depth
// discontinuity does not inflate the gradient of the pixels beside it (the
// role of Falcor's fwidth(z), but edge-aware). 0 where no neighbour qualifies
// and on sky pixels.
std::vector<vec2> depthGradient(const GuideBuffers& guides);

// Fills guides.depthGrad with depthGradient(guides) if it is empty.
void ensureDepthGradient(GuideBuffers& guides);

}  // namespace rtlab::denoise
