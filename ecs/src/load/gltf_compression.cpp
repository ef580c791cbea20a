// Draco and meshoptimizer decoding for the glTF loader (gltf_compression.hpp).
// The only translation unit that includes Draco's headers.
#include "gltf_compression.hpp"

#include <draco/compression/decode.h>
#include <draco/compression/point_cloud/point_cloud_decoder.h>
#include <draco/core/decoder_buffer.h>
#include <draco/core/varint_decoding.h>
#include <draco/metadata/geometry_metadata.h>
#include <draco/metadata/metadata_decoder.h>
#include <draco/mesh/mesh.h>
#include <meshoptimizer.h>

#include <cstring>
#include <memory>

namespace rtlab::ecs::load::compression {
namespace {

template <class T>
bool convertAll(const draco::PointAttribute& attr, std::size_t points, int components,
                std::vector<unsigned char>& out) {
    out.resize(points * static_cast<std::size_t>(components) * sizeof(T));
    std::vector<T> element(static_cast<std::size_t>(components));
    for (std::size_t p = 0; p < points; ++p) {
        const draco::AttributeValueIndex value = attr.mapped_index(draco::PointIndex(static_cast<std::uint32_t>(p)));
        if (value.value() >= attr.size()) return false;
        if (!attr.ConvertValue<T>(value, static_cast<std::int8_t>(components), element.data())) return false;
        std::memcpy(out.data() + p * element.size() * sizeof(T), element.data(), element.size() * sizeof(T));
    }
    return true;
}

bool convertAttribute(const draco::PointAttribute& attr, std::size_t points, int componentType, int components,
                      std::vector<unsigned char>& out) {
    switch (componentType) {
        case 5120: return convertAll<std::int8_t>(attr, points, components, out);
        case 5121: return convertAll<std::uint8_t>(attr, points, components, out);
        case 5122: return convertAll<std::int16_t>(attr, points, components, out);
        case 5123: return convertAll<std::uint16_t>(attr, points, components, out);
        case 5125: return convertAll<std::uint32_t>(attr, points, components, out);
        case 5126: return convertAll<float>(attr, points, components, out);
        default: return false;
    }
}

// Draco's sequential mesh decoder allocates (and zero-fills) the point count
// its header declares, up to 2^32, without checking it against the data: 30
// bytes asked for gigabytes. Reads the header (and metadata) and that count
// first; "" when it is at most `maxPoints` or the stream is not a sequential
// mesh (then Draco decodes, and reports what is wrong).
std::string checkDracoPointCount(const unsigned char* data, std::size_t size, std::size_t maxPoints) {
    draco::DecoderBuffer buffer;
    buffer.Init(reinterpret_cast<const char*>(data), size);
    draco::DracoHeader header;
    if (!draco::PointCloudDecoder::DecodeHeader(&buffer, &header).ok()) return "";
    if (header.encoder_type != draco::TRIANGULAR_MESH || header.encoder_method != draco::MESH_SEQUENTIAL_ENCODING)
        return "";
    const std::uint16_t version = DRACO_BITSTREAM_VERSION(header.version_major, header.version_minor);
    buffer.set_bitstream_version(version);
    if (header.flags & METADATA_FLAG_MASK) {
        draco::MetadataDecoder metadata;
        draco::GeometryMetadata geometry;
        if (!metadata.DecodeGeometryMetadata(&buffer, &geometry)) return "";
    }
    std::uint32_t faces = 0, points = 0;
    const bool read = version < DRACO_BITSTREAM_VERSION(2, 2)
                          ? buffer.Decode(&faces) && buffer.Decode(&points)
                          : draco::DecodeVarint(&faces, &buffer) && draco::DecodeVarint(&points, &buffer);
    if (!read || points <= maxPoints) return "";
    return "the Draco data declares " + std::to_string(points) + " points, more than its accessors' " +
           std::to_string(maxPoints);
}

}  // namespace

DracoMesh decodeDracoMesh(const unsigned char* data, std::size_t size,
                          const std::vector<DracoAttributeRequest>& requests, std::size_t maxPoints) {
    DracoMesh out;
    out.error = checkDracoPointCount(data, size, maxPoints);
    if (!out.error.empty()) return out;
    draco::DecoderBuffer buffer;
    buffer.Init(reinterpret_cast<const char*>(data), size);
    draco::Decoder decoder;
    auto decoded = decoder.DecodeMeshFromBuffer(&buffer);
    if (!decoded.ok()) {
        out.error = "cannot decode the Draco mesh (" + decoded.status().error_msg_string() + ")";
        return out;
    }
    const std::unique_ptr<draco::Mesh> mesh = std::move(decoded).value();
    if (!mesh) {
        out.error = "cannot decode the Draco mesh";
        return out;
    }
    out.points = mesh->num_points();
    out.indices.reserve(static_cast<std::size_t>(mesh->num_faces()) * 3);
    for (std::uint32_t f = 0; f < mesh->num_faces(); ++f)
        for (int k = 0; k < 3; ++k) {
            const std::uint32_t index = mesh->face(draco::FaceIndex(f))[k].value();
            if (index >= out.points) {
                out.error = "the Draco mesh has a face index out of range";
                return out;
            }
            out.indices.push_back(index);
        }
    for (const DracoAttributeRequest& r : requests) {
        const draco::PointAttribute* attr = mesh->GetAttributeByUniqueId(r.dracoId);
        if (!attr) {
            out.error = "the Draco mesh has no attribute with id " + std::to_string(r.dracoId);
            return out;
        }
        if (attr->num_components() != r.components) {
            out.error = "Draco attribute " + std::to_string(r.dracoId) + " has " +
                        std::to_string(attr->num_components()) + " components, its accessor " +
                        std::to_string(r.components);
            return out;
        }
        out.attributes.emplace_back();
        if (!convertAttribute(*attr, out.points, r.componentType, r.components, out.attributes.back())) {
            out.error = "cannot convert Draco attribute " + std::to_string(r.dracoId) + " to its accessor's type";
            return out;
        }
    }
    return out;
}

std::string decodeMeshopt(unsigned char* dst, const unsigned char* src, std::size_t srcSize, std::size_t count,
                          std::size_t stride, MeshoptMode mode, MeshoptFilter filter) {
    // The library asserts on these; check them first.
    if (count == 0) return "count must be at least 1";
    if (mode == MeshoptMode::Attributes) {
        if (stride == 0 || stride > 256 || stride % 4 != 0)
            return "byteStride " + std::to_string(stride) + " must be a multiple of 4 in [4, 256] for ATTRIBUTES";
    } else {
        if (stride != 2 && stride != 4) return "byteStride " + std::to_string(stride) + " must be 2 or 4 for indices";
        if (filter != MeshoptFilter::None) return "filters apply to ATTRIBUTES only";
        if (mode == MeshoptMode::Triangles && count % 3 != 0) return "TRIANGLES count must be a multiple of 3";
    }
    if (filter == MeshoptFilter::Octahedral && stride != 4 && stride != 8)
        return "the OCTAHEDRAL filter needs byteStride 4 or 8";
    if (filter == MeshoptFilter::Quaternion && stride != 8) return "the QUATERNION filter needs byteStride 8";

    // Decoded into aligned scratch memory: the filters work in place.
    std::vector<unsigned char> scratch(count * stride);
    int rc = 0;
    switch (mode) {
        case MeshoptMode::Attributes:
            rc = meshopt_decodeVertexBuffer(scratch.data(), count, stride, src, srcSize);
            break;
        case MeshoptMode::Triangles: rc = meshopt_decodeIndexBuffer(scratch.data(), count, stride, src, srcSize); break;
        case MeshoptMode::Indices: rc = meshopt_decodeIndexSequence(scratch.data(), count, stride, src, srcSize); break;
    }
    if (rc != 0) return "meshopt data does not decode (error " + std::to_string(rc) + ")";
    switch (filter) {
        case MeshoptFilter::None: break;
        case MeshoptFilter::Octahedral: meshopt_decodeFilterOct(scratch.data(), count, stride); break;
        case MeshoptFilter::Quaternion: meshopt_decodeFilterQuat(scratch.data(), count, stride); break;
        case MeshoptFilter::Exponential: meshopt_decodeFilterExp(scratch.data(), count, stride); break;
    }
    std::memcpy(dst, scratch.data(), scratch.size());
    return "";
}

}  // namespace rtlab::ecs::load::compression
