// Stage 3 of the glTF loader, materials and textures: glTF materials (core factors and the supported
// KHR_materials_* extensions) and the base-color images they use, converted to RGBA8 textures.
#include "gltf_internal.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace rtlab::ecs::load::gltf {

int GltfConverter::defaultMaterial() {
    if (defaultMaterial_ < 0) {
        defaultMaterial_ = static_cast<int>(s_.materials.size());
        Material m;
        m.name = "default";
        s_.materials.push_back(m);
    }
    return defaultMaterial_;
}

int GltfConverter::localMaterial(int index) {
    int& slot = materialSlot_[static_cast<std::size_t>(index)];
    if (slot < 0) {
        Material m = convertMaterial(index);
        slot = static_cast<int>(s_.materials.size());
        s_.materials.push_back(std::move(m));
    }
    return slot;
}

float GltfConverter::factor(double v, float lo, float hi, const std::string& what) const {
    if (!std::isfinite(v)) fail_(cat(what, " is not finite"));
    return std::clamp(static_cast<float>(std::clamp(v, -3.0e38, 3.0e38)), lo, hi);
}

// Number `key` of material extension `ext`, if present.
std::optional<double> GltfConverter::extensionNumber(const tg::Material& mat, const char* ext, const char* key,
                                                     const std::string& label) const {
    const auto it = mat.extensions.find(ext);
    if (it == mat.extensions.end() || !it->second.IsObject() || !it->second.Has(key)) return std::nullopt;
    const tg::Value& v = it->second.Get(key);
    if (!v.IsNumber()) fail_(cat(label, ": ", ext, ".", key, " must be a number"));
    return v.GetNumberAsDouble();
}

Material GltfConverter::convertMaterial(int index) {
    const tg::Material& mat = m_.materials[static_cast<std::size_t>(index)];
    const std::string label = materialLabel(index);
    Material out;
    out.name = mat.name.empty() ? cat("material ", index) : mat.name;
    const tg::PbrMetallicRoughness& pbr = mat.pbrMetallicRoughness;
    if (pbr.baseColorFactor.size() != 4) fail_(cat(label, ": baseColorFactor must have 4 elements"));
    for (int c = 0; c < 4; ++c)
        out.baseColor[c] =
            factor(pbr.baseColorFactor[static_cast<std::size_t>(c)], 0.f, 1.f, cat(label, " baseColorFactor"));
    out.metallic = factor(pbr.metallicFactor, 0.f, 1.f, cat(label, " metallicFactor"));
    out.roughness = factor(pbr.roughnessFactor, 0.f, 1.f, cat(label, " roughnessFactor"));

    // Every referenced texture must exist, even those we do not use.
    const std::pair<int, const char*> refs[] = {{pbr.baseColorTexture.index, "baseColorTexture"},
                                                {pbr.metallicRoughnessTexture.index, "metallicRoughnessTexture"},
                                                {mat.normalTexture.index, "normalTexture"},
                                                {mat.occlusionTexture.index, "occlusionTexture"},
                                                {mat.emissiveTexture.index, "emissiveTexture"}};
    for (const auto& [tex, name] : refs)
        if (tex >= 0) checkIndex(tex, m_.textures, "texture", cat(label, " ", name));
    if (pbr.baseColorTexture.index >= 0 && pbr.baseColorTexture.texCoord == 0)
        out.baseColorTexture = localTexture(pbr.baseColorTexture.index);

    if (!mat.emissiveFactor.empty()) {
        if (mat.emissiveFactor.size() != 3) fail_(cat(label, ": emissiveFactor must have 3 elements"));
        for (int c = 0; c < 3; ++c)
            out.emissive[c] =
                factor(mat.emissiveFactor[static_cast<std::size_t>(c)], 0.f, 1.f, cat(label, " emissiveFactor"));
    }
    if (const auto s = extensionNumber(mat, "KHR_materials_emissive_strength", "emissiveStrength", label))
        out.emissive *= factor(*s, 0.f, 3.0e38f, cat(label, " emissiveStrength"));

    if (mat.alphaMode == "OPAQUE") out.alphaMode = AlphaMode::Opaque;
    else if (mat.alphaMode == "MASK") out.alphaMode = AlphaMode::Mask;
    else if (mat.alphaMode == "BLEND") out.alphaMode = AlphaMode::Blend;
    else fail_(cat(label, ": unknown alphaMode '", mat.alphaMode, "'"));
    out.alphaCutoff = factor(mat.alphaCutoff, 0.f, 1.f, cat(label, " alphaCutoff"));
    out.doubleSided = mat.doubleSided;

    if (const auto t = extensionNumber(mat, "KHR_materials_transmission", "transmissionFactor", label))
        out.transmission = factor(*t, 0.f, 1.f, cat(label, " transmissionFactor"));
    if (const auto ior = extensionNumber(mat, "KHR_materials_ior", "ior", label))
        // The extension allows 0 ("infinite" ior); we clamp to physical values.
        out.ior = factor(*ior, 1.f, 10.f, cat(label, " ior"));
    if (const auto d = extensionNumber(mat, "KHR_materials_volume", "attenuationDistance", label)) {
        const float dist = factor(*d, 0.f, kInfinity, cat(label, " attenuationDistance"));
        out.attenuationDistance = dist > 0.f ? dist : kInfinity;  // <= 0 is invalid: no attenuation
    }
    if (const auto it = mat.extensions.find("KHR_materials_volume");
        it != mat.extensions.end() && it->second.IsObject() && it->second.Has("attenuationColor")) {
        const tg::Value& c = it->second.Get("attenuationColor");
        if (!c.IsArray() || c.ArrayLen() != 3) fail_(cat(label, ": attenuationColor must have 3 numbers"));
        for (int i = 0; i < 3; ++i) {
            if (!c.Get(i).IsNumber()) fail_(cat(label, ": attenuationColor must have 3 numbers"));
            out.attenuationColor[i] = factor(c.Get(i).GetNumberAsDouble(), 0.f, 1.f, cat(label, " attenuationColor"));
        }
    }
    return out;
}

// Local texture index for a glTF texture, or kNoTexture when it has no usable image.
std::uint32_t GltfConverter::localTexture(int textureIndex) {
    const tg::Texture& tex = m_.textures[static_cast<std::size_t>(textureIndex)];
    if (tex.sampler >= 0) checkIndex(tex.sampler, m_.samplers, "sampler", cat("texture ", textureIndex));
    if (tex.source < 0) return kNoTexture;  // e.g. only an extension source (KTX2, WebP)
    checkIndex(tex.source, m_.images, "image", cat("texture ", textureIndex));
    int& slot = imageSlot_[static_cast<std::size_t>(tex.source)];
    if (slot == -2) {
        std::optional<Texture> t = convertImage(tex.source);
        slot = t ? static_cast<int>(s_.textures.size()) : -1;
        if (t) s_.textures.push_back(std::move(*t));
    }
    return slot < 0 ? kNoTexture : static_cast<std::uint32_t>(slot);
}

std::optional<Texture> GltfConverter::convertImage(int index) const {
    const tg::Image& img = m_.images[static_cast<std::size_t>(index)];
    if (img.image.empty() || img.width <= 0 || img.height <= 0) return std::nullopt;
    if (img.component < 1 || img.component > 4 || (img.bits != 8 && img.bits != 16)) return std::nullopt;
    const auto w = static_cast<std::size_t>(img.width), h = static_cast<std::size_t>(img.height);
    const auto comp = static_cast<std::size_t>(img.component), bytes = static_cast<std::size_t>(img.bits / 8);
    if (img.image.size() != w * h * comp * bytes)
        fail_(cat("image ", index, ": decoded data has ", img.image.size(), " bytes, expected ", w * h * comp * bytes));
    Texture t;
    t.name = img.name.empty() ? (img.uri.empty() || img.uri.rfind("data:", 0) == 0 ? cat("image ", index) : img.uri)
                              : img.name;
    t.width = img.width;
    t.height = img.height;
    t.srgb = true;  // only base-color textures are loaded
    t.rgba8.resize(w * h * 4);
    const unsigned char* src = img.image.data();
    // 16-bit samples are stored in native (little-endian) order: take the high byte.
    auto sample = [&](std::size_t px, std::size_t c) -> std::uint8_t {
        return bytes == 1 ? src[px * comp + c] : src[(px * comp + c) * 2 + 1];
    };
    for (std::size_t px = 0; px < w * h; ++px) {
        std::uint8_t* d = &t.rgba8[px * 4];
        switch (comp) {
            case 1:
                d[0] = d[1] = d[2] = sample(px, 0);
                d[3] = 255;
                break;
            case 2:
                d[0] = d[1] = d[2] = sample(px, 0);
                d[3] = sample(px, 1);
                break;
            case 3:
                d[0] = sample(px, 0);
                d[1] = sample(px, 1);
                d[2] = sample(px, 2);
                d[3] = 255;
                break;
            default:
                for (std::size_t c = 0; c < 4; ++c) d[c] = sample(px, c);
                break;
        }
    }
    return t;
}

}  // namespace rtlab::ecs::load::gltf
