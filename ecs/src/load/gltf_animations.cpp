// Stage 3 of the glTF loader, animations: every animation's channels validated, those targeting nodes of
// the loaded scene converted into staged clips (paths, interpolation, key times and values).
#include "gltf_internal.hpp"

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace rtlab::ecs::load::gltf {

void GltfConverter::convertAnimations() {
    for (std::size_t a = 0; a < m_.animations.size(); ++a) {
        const tg::Animation& anim = m_.animations[a];
        const std::string label = anim.name.empty() ? cat("animation ", a) : cat("animation '", anim.name, "'");
        StagedClip clip;
        clip.name = anim.name.empty() ? cat("animation ", a) : anim.name;
        for (std::size_t c = 0; c < anim.channels.size(); ++c) {
            const tg::AnimationChannel& ch = anim.channels[c];
            const std::string where = cat(label, " channel ", c);
            checkIndex(ch.sampler, anim.samplers, "sampler", where);
            if (ch.target_node < 0) continue;  // no target node: ignored per the spec
            checkIndex(ch.target_node, m_.nodes, "node", where);
            StagedChannel out;
            out.gltfNode = ch.target_node;
            out.channel = convertChannel(anim.samplers[static_cast<std::size_t>(ch.sampler)], ch, where);
            if (s_.nodeSlot[static_cast<std::size_t>(ch.target_node)] < 0) continue;  // node not in this scene
            clip.channels.push_back(std::move(out));
        }
        if (!clip.channels.empty()) s_.clips.push_back(std::move(clip));
    }
}

AnimationChannel GltfConverter::convertChannel(const tg::AnimationSampler& sampler, const tg::AnimationChannel& ch,
                                               const std::string& where) const {
    AnimationChannel out;
    std::size_t components = 0;
    if (ch.target_path == "translation") {
        out.path = AnimationPath::Translation;
        components = 3;
    } else if (ch.target_path == "rotation") {
        out.path = AnimationPath::Rotation;
        components = 4;
    } else if (ch.target_path == "scale") {
        out.path = AnimationPath::Scale;
        components = 3;
    } else if (ch.target_path == "weights") {
        out.path = AnimationPath::Weights;
    } else {
        fail_(cat(where, ": unsupported target path '", ch.target_path, "'"));
    }
    if (out.path == AnimationPath::Weights) {
        const tg::Node& node = m_.nodes[static_cast<std::size_t>(ch.target_node)];
        if (node.mesh < 0 || static_cast<std::size_t>(node.mesh) >= m_.meshes.size() ||
            m_.meshes[static_cast<std::size_t>(node.mesh)].primitives.empty() ||
            m_.meshes[static_cast<std::size_t>(node.mesh)].primitives.front().targets.empty())
            fail_(cat(where, ": animates morph weights of ", nodeLabel(ch.target_node),
                      ", which has no mesh with morph targets"));
        components = m_.meshes[static_cast<std::size_t>(node.mesh)].primitives.front().targets.size();
    }
    out.componentsPerKey = static_cast<std::uint32_t>(components);

    std::size_t valuesPerKey = 1;
    if (sampler.interpolation == "LINEAR") out.interpolation = Interpolation::Linear;
    else if (sampler.interpolation == "STEP") out.interpolation = Interpolation::Step;
    else if (sampler.interpolation == "CUBICSPLINE") {
        out.interpolation = Interpolation::CubicSpline;
        valuesPerKey = 3;
    } else fail_(cat(where, ": unknown interpolation '", sampler.interpolation, "'"));

    const std::string inWhat = cat("input of ", where);
    const AccessorView in = view(sampler.input, inWhat, {TINYGLTF_TYPE_SCALAR}, {{kFloat}}, "SCALAR float");
    out.times = readFloats(in, inWhat);
    for (std::size_t i = 1; i < out.times.size(); ++i)
        if (out.times[i] < out.times[i - 1])
            fail_(cat("accessor ", in.index, " (", inWhat, "): key times decrease at key ", i));

    const std::string outWhat = cat("output of ", where);
    const std::vector<Format> normalizedOrFloat = {
        {kFloat}, {kByte, true}, {kUByte, true}, {kShort, true}, {kUShort, true}};
    AccessorView ov;
    switch (out.path) {
        case AnimationPath::Translation:
        case AnimationPath::Scale:
            ov = view(sampler.output, outWhat, {TINYGLTF_TYPE_VEC3}, {{kFloat}}, "VEC3 float");
            break;
        case AnimationPath::Rotation:
            ov = view(sampler.output, outWhat, {TINYGLTF_TYPE_VEC4}, normalizedOrFloat,
                      "VEC4 float or normalized integer");
            break;
        case AnimationPath::Weights:
            ov = view(sampler.output, outWhat, {TINYGLTF_TYPE_SCALAR}, normalizedOrFloat,
                      "SCALAR float or normalized integer");
            break;
    }
    out.values = readFloats(ov, outWhat);
    const std::size_t expected = out.times.size() * components * valuesPerKey;
    if (out.values.size() != expected)
        fail_(cat(where, ": output accessor ", ov.index, " has ", out.values.size(), " values, expected ", expected,
                  " (", out.times.size(), " keys x ", components, " components",
                  valuesPerKey == 3 ? " x 3 for CUBICSPLINE" : "", ")"));
    return out;
}

}  // namespace rtlab::ecs::load::gltf
