#include <rtlab/denoise/effect_layers.hpp>

#include <algorithm>
#include <stdexcept>

namespace rtlab::denoise {
namespace {

struct SignalLayer {
    std::string layer;  // "gi" (RGB) or "ao.V" (one channel)
    bool scalar = false;
};

std::vector<SignalLayer> signalsOf(const Image& frame, const std::string& effect) {
    std::vector<SignalLayer> out;
    const auto rgb = [&](const std::string& layer) {
        if (frame.hasChannel(layer + ".R")) out.push_back({layer, false});
    };
    const auto one = [&](const std::string& channel) {
        if (frame.hasChannel(channel)) out.push_back({channel, true});
    };
    if (effect == "shadows") {
        for (int i = 0; frame.hasChannel("shadow.light" + std::to_string(i) + ".V"); ++i)
            one("shadow.light" + std::to_string(i) + ".V");
        rgb("direct.point");
    } else if (effect == "reflections") {
        rgb("reflection");
    } else if (effect == "ao") {
        one("ao.V");
    } else if (effect == "gi") {
        rgb("gi");
    } else if (effect == "translucency") {
        rgb("translucency");
    } else if (effect == "volumes") {
        rgb("volume.inscatter");
        one("volume.transmittance");
    }
    return out;
}

const float* require(const Image& frame, const std::string& channel) {
    const float* c = frame.channel(channel);
    if (!c) throw std::invalid_argument("denoise: the frame has no guide channel '" + channel + "'");
    return c;
}

}  // namespace

const std::vector<std::string>& EffectLayerDenoiser::effectNames() {
    static const std::vector<std::string> names = {"shadows", "reflections", "ao", "gi", "translucency", "volumes"};
    return names;
}

EffectLayerDenoiser::EffectLayerDenoiser(std::vector<std::string> effects, const SvgfParams& params)
    : effects_(std::move(effects)), params_(params) {
    if (effects_.empty()) effects_ = effectNames();
    for (const std::string& e : effects_)
        if (std::find(effectNames().begin(), effectNames().end(), e) == effectNames().end())
            throw std::invalid_argument("denoise: unknown effect '" + e + "'");
}

std::vector<std::string> EffectLayerDenoiser::apply(Image& frame) {
    // Step: the guides, from the frame's G-buffer layers.
    const int w = frame.width(), h = frame.height();
    GuideBuffers guides(w, h);
    const float* depth = require(frame, "depth.Z");
    const float* mesh = require(frame, "id.mesh");
    const float* mx = require(frame, "motion.X");
    const float* my = require(frame, "motion.Y");
    const float* nx = require(frame, "normal.R");
    const float* ny = require(frame, "normal.G");
    const float* nz = require(frame, "normal.B");
    for (std::size_t p = 0; p < frame.pixelCount(); ++p) {
        guides.depth[p] = depth[p];
        guides.meshId[p] = mesh[p] < 0.f ? -1 : static_cast<int>(mesh[p]);
        guides.motion[p] = vec2(mx[p], my[p]);
        guides.normal[p] = vec3(nx[p], ny[p], nz[p]);
    }
    // Step: every signal of the chosen effects, in a fixed order.
    std::vector<std::string> filtered;
    for (const std::string& effect : effects_)
        for (const SignalLayer& s : signalsOf(frame, effect)) {
            std::vector<vec3> noisy(frame.pixelCount()), out(frame.pixelCount());
            if (s.scalar) {
                const float* c = frame.channel(s.layer);
                float* keep = frame.addChannel("noisy." + s.layer);
                for (std::size_t p = 0; p < noisy.size(); ++p) {
                    noisy[p] = vec3(c[p]);
                    keep[p] = c[p];
                }
            } else {
                noisy = frame.rgbLayer(s.layer);
                frame.addRgbLayer("noisy." + s.layer, noisy);
            }
            auto it = filters_.try_emplace(s.layer, params_).first;
            it->second.filter(guides, noisy, out);
            if (s.scalar) {
                float* c = frame.channel(s.layer);
                for (std::size_t p = 0; p < out.size(); ++p) c[p] = out[p].x;
            } else {
                float* r = frame.channel(s.layer + ".R");
                float* g = frame.channel(s.layer + ".G");
                float* b = frame.channel(s.layer + ".B");
                for (std::size_t p = 0; p < out.size(); ++p) {
                    r[p] = out[p].x;
                    g[p] = out[p].y;
                    b[p] = out[p].z;
                }
            }
            filtered.push_back(s.layer);
        }
    return filtered;
}

}  // namespace rtlab::denoise
