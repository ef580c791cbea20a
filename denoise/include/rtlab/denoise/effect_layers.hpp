#pragma once
// Denoising a rendered frame's effect layers (docs/effects.md names them):
// one SvgfFilter per signal layer, its history kept across frames, guided
// by the frame's own G-buffer layers (depth.Z, normal.*, id.mesh,
// motion.X/Y). Denoisers see images, never the scene. Before a layer is
// filtered its noisy values are copied to "noisy.<channel>".
//
// Signals per effect name:
//   shadows       shadow.light<i>.V (per light), direct.point.RGB
//   reflections   reflection.RGB (incoming radiance; the BRDF term stays out)
//   ao            ao.V
//   gi            gi.RGB (irradiance, albedo demodulated)
//   translucency  translucency.RGB
//   volumes       volume.inscatter.RGB, volume.transmittance
// This is the SVGF stack applied to every effect; the per-effect stacks of
// the denoise issue (footprints from penumbra, roughness, hit distance) are
// not built yet.
#include <rtlab/core/image.hpp>
#include <rtlab/denoise/svgf.hpp>

#include <map>
#include <string>
#include <vector>

namespace rtlab::denoise {

class EffectLayerDenoiser {
public:
    // `effects`: names from the table above; empty = all of them. Throws
    // std::invalid_argument for an unknown name.
    explicit EffectLayerDenoiser(std::vector<std::string> effects = {}, const SvgfParams& params = {});
    // Filters the frame's signal layers in place; returns the channels' layer
    // names that were filtered, in a fixed order. Throws std::invalid_argument
    // when the guide layers are missing.
    std::vector<std::string> apply(Image& frame);
    static const std::vector<std::string>& effectNames();

private:
    std::vector<std::string> effects_;
    SvgfParams params_;
    std::map<std::string, SvgfFilter> filters_;  // by layer name
};

}  // namespace rtlab::denoise
