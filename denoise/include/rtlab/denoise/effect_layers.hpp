#pragma once
// Denoising a rendered frame's effect layers (docs/effects.md names them):
// each signal layer gets the stack its signal deserves, built from the
// shared stages, with its history kept across frames and guided by the
// frame's own G-buffer layers (depth.Z, normal.*, id.mesh, motion.X/Y,
// footprint.pixelWorld). Denoisers see images, never the scene. Before a
// layer is filtered its noisy values are copied to "noisy.<channel>".
//
//   effect        signal layers                          stack
//   shadows       shadow.light<i>.V (one per area light)  Shadow: visibility only; footprint from the
//                                                          penumbra (shadow.light<i>.penumbra); history clamp
//                 direct.light<i>.RGB (unshadowed),       not filtered (closed-form diffuse, stratified specular;
//                 direct.point.RGB (<= 4 point lights)     each point light traced: no noise but the fog's)
//                 direct.pointPicked.RGB                  Svgf on direct.pointPicked / albedo.RGB (more than 4
//                                                          point lights, one picked per pixel; remodulated after)
//   reflections   reflection.RGB (incoming radiance)      Reflection: footprint from roughness.Y and
//                                                          reflection.hitT; history clamp
//   ao            ao.V                                    AmbientOcclusion: footprint from ao.hitT
//   gi            gi.RGB (irradiance, albedo demodulated)  Svgf (the paper's parameter set)
//   translucency  translucency.RGB                        Svgf
//   volumes       volume.inscatter.RGB, .transmittance    Svgf
//
// A frame without footprint.pixelWorld (an EXR from before it existed)
// falls back to Svgf for every layer; apply() reports the stack it used.
#include <rtlab/core/image.hpp>
#include <rtlab/denoise/footprint.hpp>
#include <rtlab/denoise/svgf.hpp>

#include <map>
#include <string>
#include <vector>

namespace rtlab::denoise {

enum class DenoiseStack { Svgf, Shadow, Reflection, AmbientOcclusion };
const char* stackName(DenoiseStack stack);

// The parameters of one stack: SVGF's stages plus the footprint rule. The
// shadow, reflection and AO stacks also guide their a-trous passes by the
// variance of the accumulated mean (SvgfParams::varianceOfMean): on
// builtin:showcase AO after 8 static frames relMSE 0.0034 -> 0.0020.
struct StackParams {
    SvgfParams svgf;
    FootprintParams footprint;

    // SVGF, the paper's set (5 iterations, alpha 0.2, sigma z/n/l 1/128/4).
    static StackParams svgfPaper();
    // The Svgf stack of `--denoise auto`: the paper's set, and static pixels
    // keep converging (SvgfParams::convergeStatic; every stack below has it too).
    static StackParams svgfAuto();
    // Shadows: the paper's set with 4 a-trous iterations and a 5x5 spatial
    // variance (lower one-frame error than 5 and 7x7, and cheaper), the
    // footprint from the penumbra, and the history clamped to mean +- 1
    // sigma of the 5x5 neighbourhood (rtlab: a moving occluder must not
    // leave a ghost shadow).
    static StackParams shadow();
    // Reflections: as shadows (4 iterations, 5x5 variance), the footprint from the glossy lobe (at
    // least 4 px: a mirror's reflection is sharp but the light sampled at the
    // reflected surface is noisy), luminance sigma 10 (Falcor's PhiColor;
    // the paper's 4 keeps a 1-spp reflection's sparse bright samples apart:
    // relMSE 0.0020 -> 0.0013 on builtin:showcase), and the same history
    // clamp as shadows (the reflected image moves with the reflected
    // surface, not with the mirror; reprojection uses the mirror's motion).
    static StackParams reflection();
    // AO: the paper's set with 4 iterations and a 5x5 variance, the
    // footprint from the occluder distance and luminance sigma 10
    // (Falcor's; relMSE 0.0071 -> 0.0051 on showcase).
    static StackParams ambientOcclusion();
    static StackParams of(DenoiseStack stack);
};

struct DenoisedLayer {
    std::string layer;   // "shadow.light0.V", "gi", ...
    std::string effect;  // "shadows", ...
    DenoiseStack stack = DenoiseStack::Svgf;
};

class EffectLayerDenoiser {
public:
    // `effects`: names from the table above; empty = all of them. Throws
    // std::invalid_argument for an unknown name. `forceSvgf` runs plain SVGF
    // on every layer (for comparisons: `rtlab converge` measures both).
    explicit EffectLayerDenoiser(std::vector<std::string> effects = {}, bool forceSvgf = false);
    // Filters the frame's signal layers in place; returns what was filtered
    // and how, in a fixed order. Throws std::invalid_argument when the guide
    // layers are missing.
    std::vector<DenoisedLayer> apply(Image& frame);
    static const std::vector<std::string>& effectNames();
    // Forgets every layer's history.
    void reset() { filters_.clear(); }

private:
    std::vector<std::string> effects_;
    bool forceSvgf_ = false;
    std::map<std::string, SvgfFilter> filters_;  // by layer name
};

}  // namespace rtlab::denoise
