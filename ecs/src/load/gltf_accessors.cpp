// Stage 3 of the glTF loader, accessors: component types and formats, bounds-checked accessor views
// (strides, sparse substitution) read as floats or indices, and the KHR_draco_mesh_compression decode whose
// attributes stand in for the accessors they name.
#include "gltf_internal.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace rtlab::ecs::load::gltf {
namespace {

int componentSize(int componentType) {
    switch (componentType) {
        case kByte:
        case kUByte: return 1;
        case kShort:
        case kUShort: return 2;
        case kUInt:
        case kFloat: return 4;
        default: return 0;
    }
}
std::string typeName(int type) {
    switch (type) {
        case TINYGLTF_TYPE_SCALAR: return "SCALAR";
        case TINYGLTF_TYPE_VEC2: return "VEC2";
        case TINYGLTF_TYPE_VEC3: return "VEC3";
        case TINYGLTF_TYPE_VEC4: return "VEC4";
        case TINYGLTF_TYPE_MAT2: return "MAT2";
        case TINYGLTF_TYPE_MAT3: return "MAT3";
        case TINYGLTF_TYPE_MAT4: return "MAT4";
        default: return cat("type ", type);
    }
}
std::string componentTypeName(int ct, bool normalized) {
    std::string n;
    switch (ct) {
        case kByte: n = "byte"; break;
        case kUByte: n = "unsigned byte"; break;
        case kShort: n = "short"; break;
        case kUShort: n = "unsigned short"; break;
        case kUInt: n = "unsigned int"; break;
        case kFloat: return "float";
        default: return cat("component type ", ct);
    }
    return normalized ? "normalized " + n : n;
}

float readFloat(const unsigned char* p, int ct, bool normalized) {
    switch (ct) {
        case kFloat: {
            float f;
            std::memcpy(&f, p, 4);
            return f;
        }
        case kByte: {
            std::int8_t v;
            std::memcpy(&v, p, 1);
            return normalized ? std::max(static_cast<float>(v) / 127.f, -1.f) : static_cast<float>(v);
        }
        case kUByte: return normalized ? static_cast<float>(p[0]) / 255.f : static_cast<float>(p[0]);
        case kShort: {
            std::int16_t v;
            std::memcpy(&v, p, 2);
            return normalized ? std::max(static_cast<float>(v) / 32767.f, -1.f) : static_cast<float>(v);
        }
        case kUShort: {
            std::uint16_t v;
            std::memcpy(&v, p, 2);
            return normalized ? static_cast<float>(v) / 65535.f : static_cast<float>(v);
        }
        case kUInt: {
            std::uint32_t v;
            std::memcpy(&v, p, 4);
            return normalized ? static_cast<float>(static_cast<double>(v) / 4294967295.0) : static_cast<float>(v);
        }
        default: return 0.f;
    }
}
std::uint32_t readUInt(const unsigned char* p, int ct) {
    switch (ct) {
        case kUByte: return p[0];
        case kUShort: {
            std::uint16_t v;
            std::memcpy(&v, p, 2);
            return v;
        }
        case kUInt: {
            std::uint32_t v;
            std::memcpy(&v, p, 4);
            return v;
        }
        default: return 0;
    }
}

}  // namespace

int componentCount(int type) {
    switch (type) {
        case TINYGLTF_TYPE_SCALAR: return 1;
        case TINYGLTF_TYPE_VEC2: return 2;
        case TINYGLTF_TYPE_VEC3: return 3;
        case TINYGLTF_TYPE_VEC4: return 4;
        case TINYGLTF_TYPE_MAT2: return 4;
        case TINYGLTF_TYPE_MAT3: return 9;
        case TINYGLTF_TYPE_MAT4: return 16;
        default: return 0;
    }
}

std::vector<vec3> GltfConverter::readVec3(int accessor, const std::string& what, std::size_t expectedCount,
                                          const std::vector<Format>& formats, const char* expected) {
    const AccessorView v = view(accessor, what, {TINYGLTF_TYPE_VEC3}, formats, expected);
    requireCount(v, what, expectedCount);
    const std::vector<float> f = readFloats(v, what);
    std::vector<vec3> out(v.count);
    for (std::size_t i = 0; i < v.count; ++i) out[i] = vec3(f[3 * i], f[3 * i + 1], f[3 * i + 2]);
    return out;
}

// Vertex attribute formats: glTF 2.0 core, widened by KHR_mesh_quantization
// when the file uses it (normalized or integer positions; integer
// normals and texture coordinates).
std::vector<vec3> GltfConverter::readPositions(int accessor, const std::string& what) {
    if (!quantized_) return readVec3(accessor, what, 0, {{kFloat}}, "VEC3 float");
    return readVec3(
        accessor, what, 0,
        {{kFloat}, {kByte, false, true}, {kUByte, false, true}, {kShort, false, true}, {kUShort, false, true}},
        "VEC3 float or (KHR_mesh_quantization) byte/short");
}

std::vector<vec3> GltfConverter::readNormals(int accessor, const std::string& what, std::size_t n) {
    if (!quantized_) return readVec3(accessor, what, n, {{kFloat}}, "VEC3 float");
    return readVec3(accessor, what, n, {{kFloat}, {kByte, true}, {kShort, true}},
                    "VEC3 float or (KHR_mesh_quantization) normalized byte/short");
}

std::vector<vec3> GltfConverter::readPositionDeltas(int accessor, const std::string& what, std::size_t n) {
    if (!quantized_) return readVec3(accessor, what, n, {{kFloat}}, "VEC3 float");
    return readVec3(accessor, what, n, {{kFloat}, {kByte, false, true}, {kShort, false, true}},
                    "VEC3 float or (KHR_mesh_quantization) byte/short");
}

// Index accessor, every index checked against the vertex count.
std::vector<std::uint32_t> GltfConverter::readIndices(int accessor, const std::string& what, std::size_t n) {
    const AccessorView v =
        view(accessor, what, {TINYGLTF_TYPE_SCALAR},
             {{kUByte, false, true}, {kUShort, false, true}, {kUInt, false, true}}, "SCALAR unsigned byte/short/int");
    std::vector<std::uint32_t> out = readUInts(v);
    for (std::size_t i = 0; i < out.size(); ++i)
        if (out[i] >= n)
            fail_(cat("accessor ", v.index, " (", what, "): index ", out[i], " at position ", i, " is out of range (",
                      n, " vertices)"));
    return out;
}

// KHR_draco_mesh_compression: decodes the primitive's Draco buffer; its
// attributes stand in for the accessors they name (in decoded_, which
// view() reads) and its faces are the primitive's indices.
std::optional<std::vector<std::uint32_t>> GltfConverter::decodeDraco(const tg::Primitive& prim,
                                                                     const std::string& where) {
    decoded_.clear();
    const auto it = prim.extensions.find("KHR_draco_mesh_compression");
    if (it == prim.extensions.end()) return std::nullopt;
    const std::string label = cat(where, " (KHR_draco_mesh_compression)");
    const tg::Value& ext = it->second;
    const int bufferView = ext.Get("bufferView").GetNumberAsInt();
    const tg::Value& attrs = ext.Get("attributes");
    std::vector<compression::DracoAttributeRequest> requests;
    std::vector<int> accessors;
    for (const std::string& semantic : attrs.Keys()) {
        const int accessor = attribute(prim, semantic.c_str());
        if (accessor < 0) continue;  // not used by the primitive: ignored
        checkIndex(accessor, m_.accessors, "accessor", cat(label, " ", semantic));
        const tg::Accessor& acc = m_.accessors[static_cast<std::size_t>(accessor)];
        if (componentCount(acc.type) == 0 || componentSize(acc.componentType) == 0)
            fail_(cat("accessor ", accessor, " (", semantic, " of ", where, "): invalid type or component type"));
        const double id = attrs.Get(semantic).GetNumberAsDouble();
        requests.push_back({static_cast<std::uint32_t>(id), acc.componentType, componentCount(acc.type)});
        accessors.push_back(accessor);
    }
    // Every accessor must hold the decoded point count: the smallest bounds it
    // (a large count on one attribute must not let Draco allocate it).
    std::size_t length = 0, maxPoints = accessors.empty() ? 0 : SIZE_MAX;
    const unsigned char* bytes = bufferViewBytes(bufferView, length, label);
    for (const int accessor : accessors)
        maxPoints = std::min<std::size_t>(maxPoints, m_.accessors[static_cast<std::size_t>(accessor)].count);
    compression::DracoMesh mesh = compression::decodeDracoMesh(bytes, length, requests, maxPoints);
    if (!mesh.error.empty()) fail_(cat(label, ": ", mesh.error));
    for (std::size_t i = 0; i < accessors.size(); ++i) {
        const tg::Accessor& acc = m_.accessors[static_cast<std::size_t>(accessors[i])];
        if (acc.count != mesh.points)
            fail_(
                cat(label, ": decodes ", mesh.points, " points but accessor ", accessors[i], " declares ", acc.count));
        decoded_[accessors[i]] = std::move(mesh.attributes[i]);
    }
    if (prim.indices >= 0) {
        checkIndex(prim.indices, m_.accessors, "accessor", cat("indices of ", label));
        const std::size_t declared = m_.accessors[static_cast<std::size_t>(prim.indices)].count;
        if (declared != mesh.indices.size())
            fail_(cat(label, ": decodes ", mesh.indices.size(), " indices but accessor ", prim.indices, " declares ",
                      declared));
    }
    return std::move(mesh.indices);
}

GltfConverter::GltfConverter(const tg::Model& model, const Fail& fail, DecodeBudget& budget,
                             const std::vector<std::pair<std::size_t, std::uint64_t>>& placeholders)
    : m_(model), fail_(fail), budget_(budget) {
    std::vector<bool> decoded(m_.buffers.size(), false);
    for (const auto& [index, bytes] : placeholders)
        if (index < decoded.size()) decoded[index] = true;
    for (std::size_t i = 0; i < m_.buffers.size(); ++i)
        if (!decoded[i]) budget_.bufferBytes += m_.buffers[i].data.size();
}

void GltfConverter::chargeDecoded(std::uint64_t bytes, const std::string& what) const {
    budget_.geometryBytes += bytes;
    if (budget_.geometryBytes > budget_.geometryLimit())
        fail_(cat(what, ": the scene decodes to more than ", budget_.geometryLimit(),
                  " bytes of geometry (1 GiB + 64 x its glTF buffers' bytes; accessors read by many primitives or "
                  "many deformable instances of one mesh)"));
}

void GltfConverter::requireCount(const AccessorView& v, const std::string& what, std::size_t expected) const {
    if (expected != 0 && v.count != expected)
        fail_(cat("accessor ", v.index, " (", what, ") has ", v.count, " elements, POSITION has ", expected));
}

// Returns the bytes of a bufferView after checking it lies in its buffer.
const unsigned char* GltfConverter::bufferViewBytes(int index, std::size_t& length, const std::string& user) const {
    checkIndex(index, m_.bufferViews, "bufferView", user);
    const tg::BufferView& bv = m_.bufferViews[static_cast<std::size_t>(index)];
    checkIndex(bv.buffer, m_.buffers, "buffer", cat("bufferView ", index));
    const std::vector<unsigned char>& data = m_.buffers[static_cast<std::size_t>(bv.buffer)].data;
    if (bv.byteLength == 0 || bv.byteOffset > data.size() || bv.byteLength > data.size() - bv.byteOffset)
        fail_(cat("bufferView ", index, " (byteOffset ", bv.byteOffset, ", byteLength ", bv.byteLength,
                  ") exceeds buffer ", bv.buffer, " (", data.size(), " bytes)"));
    length = bv.byteLength;
    return data.data() + bv.byteOffset;
}

AccessorView GltfConverter::view(int index, const std::string& what, std::initializer_list<int> types,
                                 const std::vector<Format>& formats, const char* expected) const {
    checkIndex(index, m_.accessors, "accessor", what);
    const tg::Accessor& acc = m_.accessors[static_cast<std::size_t>(index)];
    const std::string label = cat("accessor ", index, " (", what, ")");
    bool typeOk = std::find(types.begin(), types.end(), acc.type) != types.end();
    bool formatOk = false;
    for (const Format& f : formats)
        if (f.componentType == acc.componentType &&
            (f.componentType == kFloat || f.anyNorm || f.normalized == acc.normalized))
            formatOk = true;
    if (!typeOk || !formatOk)
        fail_(cat(label, ": expected ", expected, ", got ", typeName(acc.type), " ",
                  componentTypeName(acc.componentType, acc.normalized)));

    AccessorView v;
    v.index = index;
    v.acc = &acc;
    v.components = componentCount(acc.type);
    v.componentBytes = componentSize(acc.componentType);
    v.count = acc.count;
    if (v.count == 0) fail_(cat(label, ": count must be at least 1"));
    const std::size_t elementBytes = static_cast<std::size_t>(v.components * v.componentBytes);
    chargeDecoded(std::uint64_t(v.count) * std::uint64_t(v.components) * 4u, label);

    if (const auto decoded = decoded_.find(index); decoded != decoded_.end()) {
        v.data = decoded->second.data();  // Draco: count elements, tightly packed
        v.stride = elementBytes;
    } else if (acc.bufferView >= 0) {
        std::size_t viewLength = 0;
        const unsigned char* bytes = bufferViewBytes(acc.bufferView, viewLength, label);
        const std::size_t declaredStride = m_.bufferViews[static_cast<std::size_t>(acc.bufferView)].byteStride;
        v.stride = declaredStride != 0 ? declaredStride : elementBytes;
        if (v.stride < elementBytes)
            fail_(cat(label, ": byteStride ", v.stride, " is smaller than the element size ", elementBytes));
        // byteOffset + stride * (count - 1) + elementSize <= bufferView length, overflow-free.
        if (acc.byteOffset > viewLength || elementBytes > viewLength - acc.byteOffset ||
            (v.count - 1) > (viewLength - acc.byteOffset - elementBytes) / v.stride)
            fail_(cat(label, ": ", v.count, " elements at byteOffset ", acc.byteOffset, " with stride ", v.stride,
                      " exceed bufferView ", acc.bufferView, " (", viewLength, " bytes)"));
        v.data = bytes + acc.byteOffset;
    } else if (v.count > kMaxUnbackedAccessorElements) {
        fail_(cat(label, ": ", v.count, " elements without a bufferView (limit ", kMaxUnbackedAccessorElements, ")"));
    }

    if (acc.sparse.isSparse) {
        const int sc = acc.sparse.count;
        if (sc < 1 || static_cast<std::size_t>(sc) > v.count)
            fail_(cat(label, ": sparse count ", sc, " must be in [1, ", v.count, "]"));
        const auto sparseCount = static_cast<std::size_t>(sc);
        const int ict = acc.sparse.indices.componentType;
        if (ict != kUByte && ict != kUShort && ict != kUInt)
            fail_(cat(label, ": sparse indices must be unsigned byte/short/int"));
        const auto indexBytes = static_cast<std::size_t>(componentSize(ict));
        std::size_t length = 0;
        const unsigned char* ib = bufferViewBytes(acc.sparse.indices.bufferView, length, cat(label, " sparse indices"));
        const std::size_t ioff = static_cast<std::size_t>(std::max(acc.sparse.indices.byteOffset, 0));
        if (ioff > length || sparseCount > (length - ioff) / indexBytes)
            fail_(cat(label, ": sparse indices exceed bufferView ", acc.sparse.indices.bufferView));
        const unsigned char* vb = bufferViewBytes(acc.sparse.values.bufferView, length, cat(label, " sparse values"));
        const std::size_t voff = static_cast<std::size_t>(std::max(acc.sparse.values.byteOffset, 0));
        if (voff > length || sparseCount > (length - voff) / elementBytes)
            fail_(cat(label, ": sparse values exceed bufferView ", acc.sparse.values.bufferView));
        v.sparseIndices.resize(sparseCount);
        for (std::size_t i = 0; i < sparseCount; ++i) {
            const std::uint32_t target = readUInt(ib + ioff + i * indexBytes, ict);
            if (target >= v.count || (i > 0 && target <= v.sparseIndices[i - 1]))
                fail_(cat(label, ": sparse indices must be strictly increasing and < ", v.count));
            v.sparseIndices[i] = target;
        }
        v.sparseValues = vb + voff;
    }
    return v;
}

template <class T, class Read>
std::vector<T> GltfConverter::gather(const AccessorView& v, Read read) {
    const auto nc = static_cast<std::size_t>(v.components);
    const auto cs = static_cast<std::size_t>(v.componentBytes);
    std::vector<T> out(v.count * nc, T(0));
    if (v.data)
        for (std::size_t i = 0; i < v.count; ++i)
            for (std::size_t c = 0; c < nc; ++c) out[i * nc + c] = read(v.data + i * v.stride + c * cs);
    for (std::size_t k = 0; k < v.sparseIndices.size(); ++k)
        for (std::size_t c = 0; c < nc; ++c)
            out[v.sparseIndices[k] * nc + c] = read(v.sparseValues + (k * nc + c) * cs);
    return out;
}

// Reads as float (normalized integers converted per the spec); all values must be finite.
std::vector<float> GltfConverter::readFloats(const AccessorView& v, const std::string& what) const {
    const int ct = v.acc->componentType;
    const bool normalized = v.acc->normalized;
    std::vector<float> out = gather<float>(v, [&](const unsigned char* p) { return readFloat(p, ct, normalized); });
    for (std::size_t i = 0; i < out.size(); ++i)
        if (!std::isfinite(out[i]))
            fail_(cat("accessor ", v.index, " (", what, ") contains a non-finite value at element ",
                      i / static_cast<std::size_t>(v.components)));
    return out;
}

std::vector<std::uint32_t> GltfConverter::readUInts(const AccessorView& v) {
    const int ct = v.acc->componentType;
    return gather<std::uint32_t>(v, [&](const unsigned char* p) { return readUInt(p, ct); });
}

}  // namespace rtlab::ecs::load::gltf
