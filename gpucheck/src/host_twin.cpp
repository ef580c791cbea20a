// gpucheck-host DIR: the GPU check's traversal (traversal.hpp) run on the
// host over an export, every ray compared with the model's answer. The same
// code as the CUDA kernel, so CI sees the GPU path's traversal work without a GPU.
// Exit 0: every ray identical; 1: some differ; 2: unreadable input.
#include <gpucheck/files.hpp>
#include <gpucheck/traversal.hpp>

#include <cstdio>
#include <string>
#include <vector>

namespace {

struct HostStack {
    struct Entry {
        std::uint32_t bits;
        float t;
        std::uint32_t kind;
    };
    std::vector<Entry> entries;
    void push(std::uint32_t bits, float t, std::uint32_t kind) { entries.push_back({bits, t, kind}); }
    void pop(std::uint32_t& bits, float& t, std::uint32_t& kind) {
        bits = entries.back().bits;
        t = entries.back().t;
        kind = entries.back().kind;
        entries.pop_back();
    }
    void clear() { entries.clear(); }
};

}  // namespace

int main(int argc, char** argv) {
    if (argc != 2) {
        std::fprintf(stderr, "usage: gpucheck-host EXPORT_DIR (written by rtlab gpucheck-export)\n");
        return 2;
    }
    gpucheck::CheckData d;
    std::string error;
    if (!gpucheck::loadCheck(argv[1], d, error)) {
        std::fprintf(stderr, "gpucheck-host: %s\n", error.c_str());
        return 2;
    }
    const gpucheck::SceneView view{d.image.data(), d.header};
    const gpucheck::HostTables tables{d.meshes.data(), d.instances.data()};
    std::vector<gpucheck::RayOut> got(d.rays.size());
    HostStack stack;
    for (std::size_t i = 0; i < d.rays.size(); ++i) {
        stack.clear();
        gpucheck::traceRay(view, tables, d.rays[i], stack, got[i]);
    }
    const std::uint64_t mismatches = gpucheck::compareWithModel(got, d.expected);
    std::printf("gpucheck-host: %zu rays, %llu differ from the model\n", d.rays.size(),
                static_cast<unsigned long long>(mismatches));
    return mismatches ? 1 : 0;
}
