#include <rtlab/denoise/guides.hpp>

#include "detail.hpp"

#include <cmath>
#include <stdexcept>

namespace rtlab::denoise {

GuideBuffers::GuideBuffers(int w, int h) : width(w), height(h) {
    const std::size_t n = detail::pixelCount(w, h);
    depth.assign(n, 1.f);
    normal.assign(n, vec3(0.f, 0.f, 1.f));
    meshId.assign(n, 0);
    motion.assign(n, vec2(0.f));
}

void GuideBuffers::validate() const {
    const std::size_t n = detail::pixelCount(width, height);
    detail::checkSize(depth.size(), n, "GuideBuffers::depth");
    detail::checkSize(normal.size(), n, "GuideBuffers::normal");
    detail::checkSize(meshId.size(), n, "GuideBuffers::meshId");
    detail::checkSize(motion.size(), n, "GuideBuffers::motion");
    if (!depthGrad.empty()) detail::checkSize(depthGrad.size(), n, "GuideBuffers::depthGrad");
}

namespace {

// One axis of the gradient: the smaller-magnitude one-sided difference among
// the qualifying neighbours (backward wins ties, so the choice is fixed).
float axisDerivative(const GuideBuffers& g, std::size_t i, int x, int y, int dx, int dy) {
    const int id = g.meshId[i];
    const float z = g.depth[i];
    bool haveBack = false, haveFwd = false;
    float back = 0.f, fwd = 0.f;
    const int bx = x - dx, by = y - dy, fx = x + dx, fy = y + dy;
    if (bx >= 0 && by >= 0) {
        const std::size_t j = static_cast<std::size_t>(by) * g.width + bx;
        if (g.meshId[j] == id) {
            haveBack = true;
            back = z - g.depth[j];
        }
    }
    if (fx < g.width && fy < g.height) {
        const std::size_t j = static_cast<std::size_t>(fy) * g.width + fx;
        if (g.meshId[j] == id) {
            haveFwd = true;
            fwd = g.depth[j] - z;
        }
    }
    float d = 0.f;
    if (haveBack && haveFwd) d = std::fabs(fwd) < std::fabs(back) ? fwd : back;
    else if (haveBack) d = back;
    else if (haveFwd) d = fwd;
    // Any finite depth: the difference may overflow; keep the gradient finite.
    if (!(d == d)) return 0.f;
    return d < -kMaxRadiance ? -kMaxRadiance : (d > kMaxRadiance ? kMaxRadiance : d);
}

}  // namespace

std::vector<vec2> depthGradient(const GuideBuffers& g) {
    g.validate();
    std::vector<vec2> grad(g.pixelCount(), vec2(0.f));
    detail::forEachPixel(g.width, g.height, [&](int x, int y, std::size_t i) {
        if (g.isSky(i)) return;
        grad[i] = vec2(axisDerivative(g, i, x, y, 1, 0), axisDerivative(g, i, x, y, 0, 1));
    });
    return grad;
}

void ensureDepthGradient(GuideBuffers& guides) {
    if (guides.depthGrad.empty()) guides.depthGrad = depthGradient(guides);
}

}  // namespace rtlab::denoise
