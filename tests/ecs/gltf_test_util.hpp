#pragma once
// Hand-written glTF files for the loader tests: a document builder whose
// buffer 0 is embedded as a base64 data URI, plus extra buffers without data
// (EXT_meshopt_compression fallback buffers).
#include <rtlab/core/error.hpp>
#include <rtlab/core/math.hpp>
#include <rtlab/ecs/load/scene_loader.hpp>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <unistd.h>

namespace rtlab::test {

// Debian's assimp-testmodels: real third-party glTF files, valid and malformed.
inline const std::filesystem::path kModels = "/usr/share/assimp/models/glTF2";

// Loads into a fresh world; returns the InputError message or "" on success.
inline std::string loadError(const std::filesystem::path& path) {
    ecs::World world;
    try {
        ecs::load::loadGltf(world, path);
    } catch (const InputError& e) {
        return e.what();
    }
    return "";
}

// A fixture with a fresh scratch directory per test, removed afterwards.
class ScratchDirTest : public ::testing::Test {
protected:
    void SetUp() override {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        dir_ =
            std::filesystem::temp_directory_path() / ("rtlab_gltf_" + std::to_string(::getpid()) + "_" + info->name());
        std::filesystem::create_directories(dir_);
    }
    void TearDown() override {
        std::error_code ec;
        std::filesystem::remove_all(dir_, ec);
    }
    std::filesystem::path file(const std::string& name) const { return dir_ / name; }

    std::filesystem::path dir_;
};

inline std::string base64(const std::vector<std::uint8_t>& data) {
    static const char* kAlphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string out;
    std::size_t i = 0;
    for (; i + 2 < data.size(); i += 3) {
        const std::uint32_t v = (data[i] << 16) | (data[i + 1] << 8) | data[i + 2];
        for (int s = 18; s >= 0; s -= 6) out += kAlphabet[(v >> s) & 63];
    }
    if (i + 1 == data.size()) {
        const std::uint32_t v = data[i] << 16;
        out += kAlphabet[(v >> 18) & 63];
        out += kAlphabet[(v >> 12) & 63];
        out += "==";
    } else if (i + 2 == data.size()) {
        const std::uint32_t v = (data[i] << 16) | (data[i + 1] << 8);
        out += kAlphabet[(v >> 18) & 63];
        out += kAlphabet[(v >> 12) & 63];
        out += kAlphabet[(v >> 6) & 63];
        out += '=';
    }
    return out;
}

// Builds a glTF document with one buffer embedded as a data URI.
class GltfBuilder {
public:
    using Json = nlohmann::json;

    GltfBuilder() {
        doc_["asset"] = {{"version", "2.0"}};
        for (const char* k : {"accessors", "bufferViews", "meshes", "nodes"}) doc_[k] = Json::array();
    }
    // Appends raw bytes to buffer 0 (4-byte aligned); returns their offset.
    std::size_t appendBytes(const void* data, std::size_t bytes) {
        while (bin_.size() % 4) bin_.push_back(0);
        const std::size_t offset = bin_.size();
        const auto* p = static_cast<const std::uint8_t*>(data);
        bin_.insert(bin_.end(), p, p + bytes);
        return offset;
    }
    // Appends raw bytes as a new bufferView; returns its index.
    int addView(const void* data, std::size_t bytes) {
        const std::size_t offset = appendBytes(data, bytes);
        doc_["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", offset}, {"byteLength", bytes}});
        return static_cast<int>(doc_["bufferViews"].size() - 1);
    }
    // A buffer of `bytes` bytes after buffer 0, without data: an
    // EXT_meshopt_compression fallback buffer. Returns its index.
    int addFallbackBuffer(std::size_t bytes) {
        extraBuffers_.push_back(
            {{"byteLength", bytes}, {"extensions", {{"EXT_meshopt_compression", {{"fallback", true}}}}}});
        return static_cast<int>(extraBuffers_.size());
    }
    int addAccessor(int view, int componentType, std::size_t count, const char* type) {
        doc_["accessors"].push_back(
            {{"bufferView", view}, {"componentType", componentType}, {"count", count}, {"type", type}});
        return static_cast<int>(doc_["accessors"].size() - 1);
    }
    int positions(const std::vector<vec3>& p) {
        return addAccessor(addView(p.data(), p.size() * sizeof(vec3)), 5126, p.size(), "VEC3");
    }
    template <class T>
    int indices(const std::vector<T>& idx) {
        const int ct = sizeof(T) == 1 ? 5121 : sizeof(T) == 2 ? 5123 : 5125;
        return addAccessor(addView(idx.data(), idx.size() * sizeof(T)), ct, idx.size(), "SCALAR");
    }
    int mesh(Json primitives, const char* name = "m") {
        doc_["meshes"].push_back({{"name", name}, {"primitives", std::move(primitives)}});
        return static_cast<int>(doc_["meshes"].size() - 1);
    }
    int node(Json node) {
        doc_["nodes"].push_back(std::move(node));
        return static_cast<int>(doc_["nodes"].size() - 1);
    }
    Json& doc() { return doc_; }

    std::filesystem::path write(const std::filesystem::path& path) {
        Json d = doc_;
        if (!bin_.empty() || !extraBuffers_.empty()) {
            d["buffers"] = Json::array(
                {{{"byteLength", bin_.size()}, {"uri", "data:application/octet-stream;base64," + base64(bin_)}}});
            for (const Json& b : extraBuffers_) d["buffers"].push_back(b);
        }
        std::ofstream(path) << d.dump(1);
        return path;
    }

    // The same document as a binary glTF: buffer 0 is the BIN chunk.
    std::filesystem::path writeGlb(const std::filesystem::path& path) {
        Json d = doc_;
        std::vector<std::uint8_t> bin = bin_;
        while (bin.size() % 4) bin.push_back(0);
        d["buffers"] = Json::array({{{"byteLength", bin_.size()}}});
        for (const Json& b : extraBuffers_) d["buffers"].push_back(b);
        std::string json = d.dump();
        while (json.size() % 4) json += ' ';
        std::string out = "glTF";
        auto le32 = [&](std::size_t v) {
            for (int i = 0; i < 4; ++i) out += static_cast<char>((v >> (8 * i)) & 0xffu);
        };
        le32(2);
        le32(12 + 8 + json.size() + 8 + bin.size());
        le32(json.size());
        out += "JSON";
        out += json;
        le32(bin.size());
        out += std::string("BIN\0", 4);
        out.append(bin.begin(), bin.end());
        std::ofstream(path, std::ios::binary) << out;
        return path;
    }

private:
    Json doc_;
    std::vector<std::uint8_t> bin_;
    std::vector<Json> extraBuffers_;
};

}  // namespace rtlab::test
