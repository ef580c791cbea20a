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
    std::size_t capacity = 0;  // the model's deepest stack: a deeper one is a divergence
    bool push(std::uint32_t bits, float t, std::uint32_t kind) {
        if (entries.size() == capacity) return false;
        entries.push_back({bits, t, kind});
        return true;
    }
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
    stack.capacity = d.maxStackDepth;
    for (std::size_t i = 0; i < d.rays.size(); ++i) {
        stack.clear();
        // A ray stops one step past the model's count: it differs by then (and a corrupt loop ends).
        if (!gpucheck::traceRay(view, tables, d.rays[i], stack, got[i], d.expected[i].steps + 1)) {
            std::fprintf(stderr, "gpucheck-host: %s: ray %zu meets a corrupt memory image\n", argv[1], i);
            return 2;
        }
    }
    const std::uint64_t mismatches = gpucheck::compareWithModel(got, d.expected);
    std::printf("gpucheck-host: %zu rays, %llu differ from the model\n", d.rays.size(),
                static_cast<unsigned long long>(mismatches));
    return mismatches ? 1 : 0;
}
