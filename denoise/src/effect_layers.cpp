#include <rtlab/denoise/effect_layers.hpp>
#include <rtlab/denoise/modulation.hpp>

#include "detail.hpp"

#include <algorithm>
#include <array>
#include <span>
#include <stdexcept>

namespace rtlab::denoise {
namespace {

struct SignalLayer {
    std::string layer;  // "gi" (RGB) or "ao.V" (one channel)
    bool scalar = false;
    DenoiseStack stack = DenoiseStack::Svgf;
    std::string footprintSource;    // shadows: the penumbra channel
    bool demodulateAlbedo = false;  // filter colour / albedo.RGB, then multiply back (texture stays sharp)
};

std::vector<SignalLayer> signalsOf(const Image& frame, const std::string& effect) {
    std::vector<SignalLayer> out;
    const auto rgb = [&](const std::string& layer, DenoiseStack stack) {
        if (frame.hasChannel(layer + ".R")) out.push_back({layer, false, stack, {}});
    };
    const auto one = [&](const std::string& channel, DenoiseStack stack, std::string source = {}) {
        if (frame.hasChannel(channel)) out.push_back({channel, true, stack, std::move(source)});
    };
    if (effect == "shadows") {
        const auto demodulated = [&](const std::string& layer) {
            rgb(layer, DenoiseStack::Svgf);
            if (!out.empty() && out.back().layer == layer) out.back().demodulateAlbedo = true;
        };
        for (int i = 0; frame.hasChannel("shadow.light" + std::to_string(i) + ".V"); ++i) {
            const std::string layer = "shadow.light" + std::to_string(i);
            // The unshadowed light (direct.light<i>) is not filtered: its diffuse
            // term is in closed form and its specular term 16 stratified samples.
            // Filtering it blurred more than it removed (showcase at 480x270:
            // relMSE 0.00117 with SVGF on it, 0.001165 without).
            one(layer + ".V", DenoiseStack::Shadow, layer + ".penumbra");
        }
        // Point lights traced one by one (direct.point) have no noise but the
        // fog's: SVGF on them only blurred (showcase 480x270: relMSE 6.3e-4 with,
        // 2.5e-4 without). Picked per pixel (more than 4 of them) they are noisy.
        demodulated("direct.pointPicked");
    } else if (effect == "reflections") {
        rgb("reflection", DenoiseStack::Reflection);
    } else if (effect == "ao") {
        one("ao.V", DenoiseStack::AmbientOcclusion);
    } else if (effect == "gi") {
        rgb("gi", DenoiseStack::Svgf);
    } else if (effect == "translucency") {
        rgb("translucency", DenoiseStack::Svgf);
    } else if (effect == "volumes") {
        rgb("volume.inscatter", DenoiseStack::Svgf);
        one("volume.transmittance", DenoiseStack::Svgf);
    }
    return out;
}

const float* require(const Image& frame, const std::string& channel, const std::string& why = "guide") {
    const float* c = frame.channel(channel);
    if (!c) throw std::invalid_argument("denoise: the frame has no " + why + " channel '" + channel + "'");
    return c;
}

std::span<const float> channelSpan(const Image& frame, const std::string& channel, const std::string& why) {
    return {require(frame, channel, why), frame.pixelCount()};
}

// The footprint of a stack's layer (empty for Svgf).
std::vector<float> footprintOf(const Image& frame, const SignalLayer& s, const GuideBuffers& guides,
                               std::span<const float> pixelWorld, const FootprintParams& params) {
    const int w = frame.width(), h = frame.height();
    switch (s.stack) {
        case DenoiseStack::Shadow:
            return shadowFootprint(w, h, channelSpan(frame, s.footprintSource, "penumbra"), pixelWorld, guides.meshId,
                                   params);
        case DenoiseStack::Reflection:
            return reflectionFootprint(w, h, channelSpan(frame, "roughness.Y", "roughness"),
                                       channelSpan(frame, "reflection.hitT", "hit distance"), pixelWorld, guides.meshId,
                                       params);
        case DenoiseStack::AmbientOcclusion:
            return aoFootprint(w, h, channelSpan(frame, "ao.hitT", "hit distance"),
                               channelSpan(frame, "ao.V", "visibility"), pixelWorld, guides.meshId, params);
        case DenoiseStack::Svgf: break;
    }
    return {};
}

}  // namespace

const char* stackName(DenoiseStack stack) {
    switch (stack) {
        case DenoiseStack::Svgf: return "svgf";
        case DenoiseStack::Shadow: return "shadow";
        case DenoiseStack::Reflection: return "reflection";
        case DenoiseStack::AmbientOcclusion: return "ao";
    }
    return "?";
}

namespace {
// The shadow and reflection stacks' common part (their sparse 1-spp signals).
StackParams sparseSignalStack() {
    StackParams p = StackParams::svgfAuto();
    // Shrink toward the long mean only where F's bias exceeds sqrt(3) standard
    // deviations of the difference (measured on showcase: with c = 1 the
    // 8-frame error is lower but the 64-frame one is not).
    p.svgf.staticShrinkSigma2 = 3.f;
    // Each pixel's own rest taken whole: with c_own = 2 the 64-frame error
    // is higher (showcase 96x54, 8 / 64 frames: shadows 2.41e-4 / 6.43e-5,
    // reflections 3.17e-4 / 8.39e-5), and these signals show no speckle.
    p.svgf.staticShrinkOwnSigma2 = 0.f;
    p.svgf.varianceOfMean = true;
    p.svgf.historyClamp = {HistoryClampMode::MeanSigma, 2, 1.f};
    // Four a-trous iterations (reach 30 px) and a 5x5 spatial variance
    // instead of SVGF's 5 and 7x7: lower error and cheaper. Showcase, one
    // 1-spp frame denoised (rtlab converge --frames 1 --max-spp 1
    // --denoise-max-spp 1), relMSE with 5 / 7x7 -> 4 / 5x5: shadows 320x180
    // 3.24e-4 -> 3.11e-4, 480x270 2.40e-4 -> 2.28e-4; reflections 320x180
    // 1.378e-3 -> 1.33e-3, 480x270 3.046e-4 -> 3.030e-4 (3 iterations:
    // shadows 480x270 2.32e-4).
    p.svgf.atrous.iterations = 4;
    p.svgf.variance.radius = 2;
    return p;
}
}  // namespace

StackParams StackParams::svgfPaper() { return {SvgfParams::paper(), {}}; }
StackParams StackParams::svgfAuto() {
    StackParams p = svgfPaper();
    p.svgf.convergeStatic = true;
    // The static shrink: the neighbourhood's difference beyond sqrt(2)
    // standard deviations, a pixel's own rest beyond sqrt(2) of its mean; the
    // a-trous reach over the long mean falls as (8 / n)^0.5. Showcase GI
    // (96x54, tests/shaders_cpp/test_static_view_convergence.cpp), relMSE after 8 / 16 / 32 / 64
    // frames and the isolated outliers after 12 frames (reference 0.08 %),
    // first with the GI samples of before 2026-11-25:
    //   c = 1, own rest whole:  0.0159  / 0.00832 / 0.00452 / 0.0031,  1.78 %
    //   c = 1, c_own = 2:       0.00879 / 0.00479 / 0.00295 / 0.00215, 0.25 %
    //   c = 3, c_own = 2:       0.00683 / 0.00399 / 0.00271 / 0.00203, 0.18 %
    //   no shrink:              0.00619 / 0.00387 / 0.0027  / 0.00207, 0.10 %
    //   c = 3, c_own = 2, reach (8 / n)^0.5:
    //                           0.00683 / 0.00363 / 0.00244 / 0.0017,  0.16 %
    // (reach exponent 0.25: 0.00182 after 64 frames, 0.75: 0.00204). c = 1
    // met 64 / 8 <= 1/4 only by being worse after 8 frames, and at 640x360
    // it left a visible grain on the walls; the shorter reach is what lowers
    // the late error (shadows, whose stack inherits it: 6.07e-5 -> 5.94e-5).
    // Then with the light pick that follows glossy highlights and the lobe
    // MIS at glossy hits (lighting.hpp pickLight, indirect_shading.hpp;
    // reference 0.06 %; the reach 0.5 throughout):
    //   c = 1:                  0.00402 / 0.0021  / 0.00143 / 0.00104  (0.258)
    //   c = 2:                  0.00338 / 0.00183 / 0.0013  / 0.000833 (0.246)
    //   c = 3:                  0.00318 / 0.00178 / 0.00129 / 0.000826 (0.260)
    // c = 2 is 6 % above c = 3 after 8 frames and meets 1/4 after 64. Its
    // grain at 640x360 after 12 frames (mean |L - its 8 neighbours' mean| of
    // the 8-bit luminance, `rtlab render --frames 12 --effects gi`) is 0.92
    // (c = 3: 0.85; the samples of before with c = 3: 1.08). The other SVGF
    // stacks hardly move (`rtlab converge --width 160 --height 90
    // --reference-spp 2048 --max-spp 1 --denoise-max-spp 1 --frames 64`, 8 /
    // 64 frames): translucency c = 3 1.09e-4 / 2.34e-5, c = 2 1.08e-4 /
    // 2.31e-5; volumes c = 3 1.39e-4 / 3.96e-5, c = 2 1.43e-4 / 3.96e-5.
    p.svgf.staticShrinkSigma2 = 2.f;
    p.svgf.staticShrinkOwnSigma2 = 2.f;
    p.svgf.staticReachExponent = 0.5f;
    return p;
}
StackParams StackParams::shadow() {
    StackParams p = sparseSignalStack();
    // Three a-trous iterations (reach 14 px) with a luminance weight of
    // sigmaL 8: a 1-spp visibility is 0 or 1, and with sigmaL 4 the taps of
    // a wide penumbra stopped at the other samples' noise and left blotches
    // (streaks on showcase's floor under the hovering panel). Showcase, one
    // 1-spp frame denoised (rtlab converge --effect shadows --max-spp 1
    // --frames 1 --denoise-max-spp 1), relMSE / FLIP, sigmaL 4 with 4
    // iterations -> sigmaL 8 with 3: 480x270 2.24e-4 / 0.0120 -> 1.44e-4 /
    // 0.0118; 320x180 3.10e-4 / 0.0143 -> 2.28e-4 / 0.0145; 640x360
    // (1024-spp reference) 1.86e-4 / 0.0114 -> 1.05e-4 / 0.0105. With
    // history (--frames 16), 480x270 after 2 / 8 / 16 frames: 1.07e-4 /
    // 6.76e-5 / 4.52e-5 -> 9.28e-5 / 5.69e-5 / 3.75e-5. Tried at 480x270 /
    // 320x180: sigmaL 6 with 4 iterations 1.63e-4 / 2.56e-4; with 3,
    // sigmaL 5 1.81e-4 / 2.55e-4, 6 1.59e-4 / 2.36e-4, 10 1.42e-4 / 2.32e-4,
    // 12 1.44e-4 / 2.40e-4; sigmaL 8 with 2 iterations 2.11e-4 / 2.65e-4.
    p.svgf.atrous.sigmaL = 8.f;
    p.svgf.atrous.iterations = 3;
    return p;
}
StackParams StackParams::reflection() {
    StackParams p = sparseSignalStack();
    // Two iterations at least: the light at the reflected hit is noisy even
    // where the lobe is narrow. 8 px blurred the glossy floor's images of the
    // boxes' edges (showcase, rtlab converge, denoised relMSE at 1 / 4 spp:
    // 480x270 3.8e-4 / 2.1e-4 with 8, 3.0e-4 / 1.6e-4 with 4; 320x180
    // 8.9e-4 / 3.7e-4 with 8, 1.4e-3 / 2.9e-4 with 4; 2 px: noisier at 1 spp).
    p.footprint.floorPx = 4.f;
    // Mirrors and near-mirrors (roughness < 0.05: a lobe alpha below 0.0025,
    // a 10 m reflected distance spreads < 5 cm) stay sharp: no floor, no
    // neighbours' footprint; temporal accumulation removes their noise.
    p.footprint.sharpBelowRoughness = 0.05f;
    // Edges of the reflected image (the glossy floor's images of the boxes'
    // sides and of the sphere's rim held most of the denoised error): one
    // iteration where the window's hit distances span more than 4x. Showcase
    // (rtlab converge --max-spp 1 --frames 1 --denoise-max-spp 1), relMSE /
    // FLIP without -> with: 480x270 3.03e-4 / 0.0352 -> 2.94e-4 / 0.0324,
    // 320x180 1.331e-3 / 0.0441 -> 1.317e-3 / 0.0393, 640x360 (1024-spp
    // reference) 4.58e-4 / 0.0308 -> 4.55e-4 / 0.0295; after 8 and 16 static
    // frames (480x270) +0.2 % and +0.6 %. Ratio 3: 480x270 3.31e-4; 6:
    // 2.94e-4 / 0.0331; a 3x3 window with ratio 3: 3.04e-4 / 0.0344; no
    // filter at all there (cap 0): 1.42e-3.
    p.footprint.edgeHitRatio = 4.f;
    p.footprint.edgeCapPx = 2.f;
    p.svgf.atrous.sigmaL = 10.f;
    // Depth weights against the centre's tangent plane (the glossy floor
    // recedes: the paper's term let the taps across it through and held
    // those along it at about exp(-1) each). One 1-spp frame denoised
    // (rtlab converge --effect reflections --max-spp 1 --frames 1
    // --denoise-max-spp 1), relMSE / FLIP: 480x270 2.93e-4 / 0.0322 ->
    // 2.78e-4 / 0.0321, 320x180 1.317e-3 / 0.0391 -> 1.119e-3 / 0.0400,
    // 640x360 (1024-spp reference) 4.56e-4 / 0.0293 -> 3.87e-4 / 0.0289;
    // with history (--frames 16) after 4 / 8 / 16 frames 480x270 1.30e-4 /
    // 1.10e-4 / 5.77e-5 -> 1.19e-4 / 1.02e-4 / 5.64e-5, 320x180 2.06e-4 /
    // 1.37e-4 / 8.23e-5 -> 1.94e-4 / 1.32e-4 / 8.46e-5. Shadows (1.44e-4 ->
    // 1.54e-4 at 480x270) and AO (FLIP 0.0132 -> 0.0140) keep the paper's.
    p.svgf.atrous.depthFromPlane = true;
    // A glossy floor seeing a light's image in the mirror sphere: a bright,
    // sparse 1-spp signal among dim neighbours. Its long mean takes the
    // samples as they are (a firefly clamp pulled it to the neighbours: 64-frame
    // error 3.3e-4 instead of 4.5e-5 on showcase) and restarts only beyond its
    // own samples' variance.
    p.svgf.staticResetOwnVariance = true;
    return p;
}
StackParams StackParams::ambientOcclusion() {
    StackParams p = svgfAuto();
    // Shrink toward the long mean where F's bias exceeds one standard
    // deviation of the difference: lower at 8 and at 64 frames than c = 3
    // (showcase 96x54, relMSE after 8 / 64 frames, with c_own = 2: c = 1
    // 0.00501 / 0.0011, c = 3 0.00528 / 0.00133, c = 9 0.00537 / 0.00155;
    // before c_own, with the footprint's first version: c = 2 0.00543 /
    // 0.00127, c = 3 0.00539 / 0.00138).
    p.svgf.staticShrinkSigma2 = 1.f;
    p.svgf.varianceOfMean = true;
    // sigmaL 16 (Falcor's 10 before): one 1-spp frame denoised on showcase
    // (rtlab converge --effect ao --max-spp 1 --frames 1 --denoise-max-spp
    // 1), relMSE / FLIP 10 -> 16: 480x270 1.28e-3 / 0.0135 -> 1.15e-3 /
    // 0.0132, 320x180 2.00e-3 / 0.0153 -> 1.84e-3 / 0.0153, 640x360
    // (1024-spp reference) 1.065e-3 / 0.0121 -> 0.928e-3 / 0.0114; with
    // history (--frames 16) within 1 % after 8 and 16 frames. sigmaL 24:
    // 1.12e-3 / 1.81e-3 but FLIP 0.0134 / 0.0156; 40: 1.14e-3 / 1.82e-3.
    p.svgf.atrous.sigmaL = 16.f;
    // A softer normal weight than SVGF's 128: on a curved surface at low
    // resolution (showcase's sphere at 320x180 turns about 3 degrees a pixel)
    // 128 let only the first two a-trous steps through, and the sphere's
    // contact half stayed speckled. Creases (normals 90 degrees apart) are
    // still cut. 1-spp relMSE on showcase (rtlab converge --effect ao
    // --frames 1 --max-spp 1): 320x180 0.00248 -> 0.00216, 480x270 0.0017 ->
    // 0.00154; sigmaN 64 0.00224 / 0.00158, 16 0.00221 / 0.00156.
    p.svgf.atrous.sigmaN = 32.f;
    // Four a-trous iterations and a 5x5 spatial variance (as the shadow and
    // reflection stacks): the fifth iteration's taps 16-32 px away smeared
    // the open floor's and walls' AO more than they removed noise. One 1-spp
    // frame denoised, relMSE 5 / 7x7 -> 4 / 5x5: 320x180 0.00214 -> 0.00208,
    // 480x270 0.00152 -> 0.00142, 640x360 0.00114 -> 0.00105 (SSIM 0.9489 ->
    // 0.9492); 5 iterations with 5x5: 0.00114 at 640x360. Static views are
    // unchanged (StaticConvergence: AO 64/8 0.206).
    p.svgf.atrous.iterations = 4;
    p.svgf.variance.radius = 2;
    return p;
}
StackParams StackParams::of(DenoiseStack stack) {
    switch (stack) {
        case DenoiseStack::Shadow: return shadow();
        case DenoiseStack::Reflection: return reflection();
        case DenoiseStack::AmbientOcclusion: return ambientOcclusion();
        case DenoiseStack::Svgf: break;
    }
    return svgfAuto();
}

const std::vector<std::string>& EffectLayerDenoiser::effectNames() {
    static const std::vector<std::string> names = {"shadows", "reflections", "ao", "gi", "translucency", "volumes"};
    return names;
}

EffectLayerDenoiser::EffectLayerDenoiser(std::vector<std::string> effects, bool forceSvgf)
    : effects_(std::move(effects)), forceSvgf_(forceSvgf) {
    if (effects_.empty()) effects_ = effectNames();
    for (const std::string& e : effects_)
        if (std::find(effectNames().begin(), effectNames().end(), e) == effectNames().end())
            throw std::invalid_argument("denoise: unknown effect '" + e + "'");
}

std::vector<DenoisedLayer> EffectLayerDenoiser::apply(Image& frame) {
    // Step: the guides, from the frame's G-buffer layers.
    const int w = frame.width(), h = frame.height();
    const std::size_t n = frame.pixelCount();
    GuideBuffers guides(w, h);
    const float* depth = require(frame, "depth.Z");
    const float* mesh = require(frame, "id.mesh");
    const float* mx = require(frame, "motion.X");
    const float* my = require(frame, "motion.Y");
    const float* nx = require(frame, "normal.R");
    const float* ny = require(frame, "normal.G");
    const float* nz = require(frame, "normal.B");
    detail::forEachIndex(n, [&](std::size_t p) {
        guides.depth[p] = depth[p];
        guides.meshId[p] = mesh[p] < 0.f ? -1 : static_cast<int>(mesh[p]);
        guides.motion[p] = vec2(mx[p], my[p]);
        guides.normal[p] = vec3(nx[p], ny[p], nz[p]);
    });
    ensureDepthGradient(guides);
    // The pixel's width on the surface (not across the ray): the footprints'
    // unit. Showcase, one 1-spp frame denoised (rtlab converge --max-spp 1
    // --frames 1 --denoise-max-spp 1), relMSE / FLIP across the ray -> on
    // the surface (area-equivalent, pixelWorld / sqrt(cos)): AO 480x270
    // 1.42e-3 / 0.0144 -> 1.28e-3 / 0.0135, 320x180 2.08e-3 / 0.0164 -> 2.00e-3
    // / 0.0153; shadows 2.28e-4 / 0.0123 -> 2.24e-4 / 0.0120, 3.11e-4 / 0.0146
    // -> 3.10e-4 / 0.0143; reflections 2.94e-4 / 0.0324 -> 2.93e-4 / 0.0322,
    // 1.317e-3 / 0.0393 -> 1.317e-3 / 0.0391. The slope's full 1 / cos: AO
    // 1.63e-3 / 2.63e-3 (too narrow across the slope); (1 / cos)^(1/4): AO
    // 1.30e-3 / 1.91e-3.
    const float* pixelWorldChannel = frame.channel("footprint.pixelWorld");
    const std::vector<float> onSurface =
        pixelWorldChannel ? surfacePixelWorld(std::span<const float>(pixelWorldChannel, n), guides.depthGrad)
                          : std::vector<float>();
    const std::span<const float> pixelWorld = onSurface;

    // Step: every signal of the chosen effects, in a fixed order.
    std::vector<DenoisedLayer> filtered;
    for (const std::string& effect : effects_)
        for (SignalLayer& s : signalsOf(frame, effect)) {
            if (forceSvgf_ || pixelWorld.empty()) s.stack = DenoiseStack::Svgf;
            // A forced comparison runs the paper's SVGF as published.
            StackParams params = forceSvgf_ ? StackParams::svgfPaper() : StackParams::of(s.stack);
            // The shadows' point-light layer (SVGF stack): the shadow stack's
            // shrink, c = 3 and each pixel's rest whole (measured on showcase:
            // with c = 1 the shadows' 64-frame error is not lower).
            if (s.demodulateAlbedo && !forceSvgf_) {
                const SvgfParams shadow = StackParams::shadow().svgf;
                params.svgf.staticShrinkSigma2 = shadow.staticShrinkSigma2;
                params.svgf.staticShrinkOwnSigma2 = shadow.staticShrinkOwnSigma2;
            }
            const std::vector<float> footprint = footprintOf(frame, s, guides, pixelWorld, params.footprint);
            std::vector<vec3> noisy;
            if (s.scalar) {
                noisy.resize(n);
                const float* c = frame.channel(s.layer);
                float* keep = frame.addChannel("noisy." + s.layer);
                detail::forEachIndex(n, [&](std::size_t p) {
                    noisy[p] = vec3(c[p]);
                    keep[p] = c[p];
                });
            } else {
                noisy = frame.rgbLayer(s.layer);
                frame.addRgbLayer("noisy." + s.layer, noisy);
            }
            std::vector<vec3> out(n);
            std::vector<vec3> albedo;
            if (s.demodulateAlbedo && frame.hasChannel("albedo.R")) {
                albedo = frame.rgbLayer("albedo");
                demodulate(noisy, albedo, noisy);
            }
            auto it = filters_.try_emplace(s.layer, params.svgf).first;
            it->second.setParams(params.svgf);
            it->second.filter(guides, noisy, out, footprint);
            if (!albedo.empty()) remodulate(out, albedo, out);
            if (s.scalar) {
                float* c = frame.channel(s.layer);
                detail::forEachIndex(n, [&](std::size_t p) { c[p] = out[p].x; });
            } else {
                const std::array<float*, 3> rgb = {frame.channel(s.layer + ".R"), frame.channel(s.layer + ".G"),
                                                   frame.channel(s.layer + ".B")};
                detail::forEachIndex(n, [&](std::size_t p) {
                    rgb[0][p] = out[p].x;
                    rgb[1][p] = out[p].y;
                    rgb[2][p] = out[p].z;
                });
            }
            filtered.push_back({s.layer, effect, s.stack});
        }
    return filtered;
}

}  // namespace rtlab::denoise
