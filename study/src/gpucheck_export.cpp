// rtlab gpucheck-export (docs/validation.md): the model's memory image, the
// selected rays, the model's answers and its prediction, as files the CUDA
// check (gpucheck/) reads on a machine without rtlab.
#include <rtlab/core/error.hpp>
#include <rtlab/core/image.hpp>
#include <rtlab/rtcore_sim/layout.hpp>
#include <rtlab/rtcore_sim/rtcore.hpp>
#include <rtlab/rtcore_sim/rtcore_backend.hpp>
#include <rtlab/rtcore_sim/traversal.hpp>
#include <rtlab/study/gpucheck_export.hpp>

#include <gpucheck/format.hpp>

#include <bit>
#include <cstring>
#include <fstream>
#include <limits>
#include <numeric>
#include <stdexcept>

namespace rtlab::study {
namespace {

using rtcore_sim::LaunchLog;

// The verdicts the check can replay as a rule: every candidate committed, or
// the first committed and the search ended.
class PolicySide final : public rtcore_sim::ProgrammableSide {
public:
    explicit PolicySide(const std::vector<gpucheck::RayIn>& rays) : rays_(rays) {}
    rtcore_sim::CandidateVerdict triangle(std::uint32_t i, const rtcore_sim::TriangleCandidate&) override {
        return {true, rays_[i].policy == gpucheck::kFirstHit, false};
    }
    rtcore_sim::ProceduralVerdict procedural(std::uint32_t, const rtcore_sim::ProceduralCandidate&) override {
        throw std::logic_error("gpucheck export: procedural candidate in a triangle-only scene");
    }
    bool concurrent() const override { return true; }

private:
    const std::vector<gpucheck::RayIn>& rays_;
};

// A ray's policy from its recorded verdict words, or -1 when neither rule gives them.
int policyOf(std::span<const std::uint32_t> words) {
    if (words.size() == 1 && words[0] == (LaunchLog::kCommit | LaunchLog::kEndSearch)) return gpucheck::kFirstHit;
    for (const std::uint32_t w : words)
        if (w != LaunchLog::kCommit) return -1;
    return gpucheck::kCommitAll;
}

// The model's memory image (format.hpp) at MemoryLayout's addresses.
struct MemoryImage {
    std::vector<std::uint32_t> words;
    std::vector<gpucheck::MeshInfo> meshes;
    std::vector<gpucheck::InstanceInfo> instances;
    gpucheck::SceneHeader header{};

    void put(std::uint64_t address, std::uint32_t v) { words.at(address >> 2) = v; }
    void putFloat(std::uint64_t address, float v) { put(address, std::bit_cast<std::uint32_t>(v)); }
};

// Leaf byte offsets from the region's leaf base, in leaf order (as MemoryLayout places them).
std::vector<std::uint32_t> leafOffsets(const rtcore_sim::Bvh& bvh, std::uint32_t slotBytes, const std::string& where) {
    std::vector<std::uint32_t> offsets(bvh.leaves.size());
    for (std::size_t i = 0; i < bvh.leaves.size(); ++i) {
        const std::uint64_t o =
            std::uint64_t(rtcore_sim::kLeafHeaderBytes) * i + std::uint64_t(slotBytes) * bvh.leaves[i].firstRef;
        if (o >= gpucheck::kLeafBit)
            throw InputError(where,
                             "the scene has a BVH of over 2 GiB of leaves (the check addresses leaves in 31 bits)");
        offsets[i] = static_cast<std::uint32_t>(o);
    }
    return offsets;
}

std::uint32_t refBits(rtcore_sim::NodeRef ref, const std::vector<std::uint32_t>& offsets) {
    if (!ref.valid()) return gpucheck::kInvalidRef;
    return ref.isLeaf() ? (gpucheck::kLeafBit | offsets[ref.index()]) : ref.index();
}

void writeNodes(MemoryImage& image, const rtcore_sim::Bvh& bvh, std::uint64_t nodeBase, std::uint32_t nodeBytes,
                std::uint32_t width, const std::vector<std::uint32_t>& offsets) {
    for (std::size_t n = 0; n < bvh.nodes.size(); ++n) {
        const rtcore_sim::BvhNode& node = bvh.nodes[n];
        const std::uint64_t at = nodeBase + std::uint64_t(nodeBytes) * n;
        image.put(at, node.childCount);
        for (std::uint32_t i = 0; i < width; ++i) {
            const std::uint64_t c = at + rtcore_sim::kNodeHeaderBytes + std::uint64_t(rtcore_sim::kNodeChildBytes) * i;
            const bool used = i < node.childCount;
            for (int a = 0; a < 3; ++a) {
                image.putFloat(c + 4 * a, used ? node.childBounds[i].lo[a] : 0.f);
                image.putFloat(c + 12 + 4 * a, used ? node.childBounds[i].hi[a] : 0.f);
            }
            image.put(c + 24, used ? refBits(node.children[i], offsets) : gpucheck::kInvalidRef);
        }
    }
}

MemoryImage buildImage(const rtcore_sim::ModelScene& scene, const rtcore_sim::MemoryLayout& layout,
                       const std::string& where) {
    using namespace rtcore_sim;
    MemoryImage image;
    image.words.assign(layout.totalBytes() / 4, 0u);
    const std::uint32_t width = scene.params().width;
    const std::uint32_t nodeSize = layout.nodeSize();
    gpucheck::SceneHeader& h = image.header;
    std::memcpy(h.magic, "RTLGCSCN", 8);
    h.version = gpucheck::kFormatVersion;
    h.width = width;
    h.nodeBytes = nodeSize;
    h.meshCount = static_cast<std::uint32_t>(scene.meshSlots());
    h.instanceCount = static_cast<std::uint32_t>(scene.instances().size());
    h.imageBytes = layout.totalBytes();
    h.tlasMagnitude = scene.tlasMagnitude();
    h.tlasConditioning = scene.tlasConditioning();
    h.farScale = kSlabFarScale;
    if (scene.instances().size() >= (1u << gpucheck::kInstanceIndexBits))
        throw InputError(where, "more than 2^24 instances");

    // Step: the TLAS, its leaves holding (instance | mask << 24).
    const Bvh& tlas = scene.tlas();
    h.tlasNodeBase = layout.tlasBase();
    h.tlasLeafBase = h.tlasNodeBase + std::uint64_t(tlas.nodes.size()) * nodeSize;
    const std::vector<std::uint32_t> tlasOffsets = leafOffsets(tlas, kTlasRefBytes, where);
    h.tlasRoot = refBits(tlas.root, tlasOffsets);
    writeNodes(image, tlas, h.tlasNodeBase, nodeSize, width, tlasOffsets);
    for (std::size_t l = 0; l < tlas.leaves.size(); ++l) {
        const BvhLeaf& leaf = tlas.leaves[l];
        if (leaf.refCount > gpucheck::kMaxTlasLeafRefs) throw InputError(where, "a TLAS leaf over 32 instances");
        const std::uint64_t at = h.tlasLeafBase + tlasOffsets[l];
        if (at != layout.tlasLeaf(leaf, static_cast<std::uint32_t>(l)).address)
            throw std::logic_error("gpucheck export: TLAS leaf address differs from the layout's");
        image.put(at, leaf.refCount);
        for (std::uint32_t r = 0; r < leaf.refCount; ++r) {
            const std::uint32_t instance = tlas.refs[leaf.firstRef + r].primitive;
            image.put(at + 8 + 4 * r,
                      instance | (std::uint32_t(scene.instances()[instance].mask) << gpucheck::kInstanceIndexBits));
        }
    }
    // Step: the instance table, and the exact transforms beside it.
    h.instanceBase = layout.instanceTableBase();
    for (std::size_t i = 0; i < scene.instances().size(); ++i) {
        const ModelInstance& inst = scene.instances()[i];
        const std::uint64_t at = layout.instance(static_cast<std::uint32_t>(i)).address;
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 4; ++c) image.putFloat(at + 4 * (4 * r + c), inst.worldFromObject[c][r]);
        image.put(at + 48, inst.mesh);
        image.put(at + 52, inst.mask);
        image.put(at + 60, static_cast<std::uint32_t>(i));
        gpucheck::InstanceInfo info;
        for (int c = 0; c < 4; ++c)
            for (int r = 0; r < 3; ++r) info.objectFromWorld[c][r] = inst.objectFromWorld[c][r];
        image.instances.push_back(info);
    }
    // Step: every BLAS, its leaves holding the triangles' vertices and ids.
    for (std::uint32_t m = 0; m < scene.meshSlots(); ++m) {
        gpucheck::MeshInfo info{0, 0, gpucheck::kInvalidRef, 0.f};
        const Blas* blas = scene.blas(m);
        if (blas) info.magnitude = blas->magnitude;
        if (blas && blas->hasProcedural)
            throw InputError(where, "the scene has procedural geometry (the GPU check traces triangles only)");
        if (blas && !blas->bvh.empty()) {
            const Bvh& bvh = blas->bvh;
            info.nodeBase =
                bvh.nodes.empty() ? layout.blasLeaf(m, bvh.leaves[0], 0).address : layout.blasNode(m, 0).address;
            info.leafBase = info.nodeBase + std::uint64_t(bvh.nodes.size()) * nodeSize;
            const std::vector<std::uint32_t> offsets = leafOffsets(bvh, kBlasSlotBytes, where);
            info.root = refBits(bvh.root, offsets);
            writeNodes(image, bvh, info.nodeBase, nodeSize, width, offsets);
            for (std::size_t l = 0; l < bvh.leaves.size(); ++l) {
                const BvhLeaf& leaf = bvh.leaves[l];
                const std::uint64_t at = info.leafBase + offsets[l];
                if (at != layout.blasLeaf(m, leaf, static_cast<std::uint32_t>(l)).address)
                    throw std::logic_error("gpucheck export: BLAS leaf address differs from the layout's");
                image.put(at, leaf.refCount);
                for (std::uint32_t r = 0; r < leaf.refCount; ++r) {
                    const std::uint64_t s = at + 8 + std::uint64_t(kBlasSlotBytes) * r;
                    const Triangle& tri = blas->triangles[leaf.firstRef + r];
                    for (int k = 0; k < 3; ++k)
                        for (int a = 0; a < 3; ++a) image.putFloat(s + 4 * (3 * k + a), tri.v[k][a]);
                    image.put(s + 36, bvh.refs[leaf.firstRef + r].geometry);
                    image.put(s + 40, bvh.refs[leaf.firstRef + r].primitive);
                }
            }
        }
        image.meshes.push_back(info);
    }
    return image;
}

// What the timing model fetches for a step (core_cycle.cpp's rule).
rtcore_sim::MemoryRange fetchRange(const rtcore_sim::StepInfo& st, const rtcore_sim::ModelScene& scene,
                                   const rtcore_sim::MemoryLayout& layout) {
    using rtcore_sim::StepKind;
    switch (st.kind) {
        case StepKind::Instance: return layout.instance(st.index);
        case StepKind::TlasLeaf: return layout.tlasLeaf(scene.tlas().leaves[st.index], st.index);
        case StepKind::BlasLeaf: return layout.blasLeaf(st.mesh, scene.blas(st.mesh)->bvh.leaves[st.index], st.index);
        case StepKind::Node: break;
    }
    return st.tlas ? layout.tlasNode(st.index) : layout.blasNode(st.mesh, st.index);
}

template <class T>
void writeBinary(const std::filesystem::path& path, const void* header, std::size_t headerBytes,
                 const std::vector<T>& body, const void* extra = nullptr, std::size_t extraBytes = 0) {
    writeFileAtomically(path, [&](const std::filesystem::path& tmp) {
        std::ofstream f(tmp, std::ios::binary);
        f.write(static_cast<const char*>(header), static_cast<std::streamsize>(headerBytes));
        if (extra) f.write(static_cast<const char*>(extra), static_cast<std::streamsize>(extraBytes));
        f.write(reinterpret_cast<const char*>(body.data()), static_cast<std::streamsize>(body.size() * sizeof(T)));
        f.close();
        if (f.fail()) throw InputError(path.string(), "cannot write (disk full?)");
    });
}

}  // namespace

GpuCheckExportResult exportGpuCheck(const RayTraceFile& file, const rtcore_sim::ModelScene& scene,
                                    const rtcore_sim::RtCoreConfig& config, const GpuCheckSelection& selection,
                                    const std::filesystem::path& out) {
    using namespace rtcore_sim;
    const RayTraceInfo info = file.info();
    if (!info.verdicts)
        throw InputError(file.path().string(),
                         "carries no candidate verdicts: record it on the model in launch mode "
                         "(rtlab render --backend rtcore --record-rays DIR)");
    GpuCheckExportResult result;

    // Step: the selected rays, each with the rule its recorded verdicts follow.
    std::vector<gpucheck::RayIn> rays;
    std::vector<SimRay> simRays;
    std::vector<const RayRecord*> records;
    for (const RayTraceFile::Batch& batch : file.batches()) {
        const std::uint32_t type = batch.record->rayContribution & 0xf;
        std::uint64_t word = 0;
        for (std::size_t k = 0; k < batch.rays.size(); ++k) {
            const std::span<const std::uint32_t> words = batch.verdicts.subspan(word, batch.links[k].verdicts);
            word += batch.links[k].verdicts;
            if (!((selection.rayTypeMask >> type) & 1u)) continue;
            const tracer::RayDesc desc = rayOf(batch.rays[k]);
            if (!tracer::isValidRay(desc)) {
                ++result.invalidRays;
                continue;
            }
            const int policy = policyOf(words);
            if (policy < 0) {
                ++result.otherVerdicts;
                continue;
            }
            if (selection.maxRays && rays.size() == selection.maxRays) {
                ++result.beyondMaxRays;
                continue;
            }
            const SimRay s = simRayOf(desc, batch.args());
            gpucheck::RayIn in{};
            for (int a = 0; a < 3; ++a) {
                in.origin[a] = s.ray.origin[a];
                in.direction[a] = s.ray.direction[a];
            }
            in.tMin = s.ray.tMin;
            in.tMax = s.ray.tMax;
            in.mask = s.ray.mask;
            in.policy = static_cast<std::uint32_t>(policy);
            in.skipTriangles = s.skipTriangles ? 1u : 0u;
            rays.push_back(in);
            simRays.push_back(s);
            records.push_back(&batch.rays[k]);
        }
    }
    if (rays.empty()) throw InputError(file.path().string(), "no ray of the selected ray types to export");
    if (rays.size() > kMaxLaunchThreads)
        throw InputError(file.path().string(),
                         std::to_string(rays.size()) + " selected rays: more than one launch holds (use --max-rays)");

    // Step: the memory image at the layout's addresses.
    MemoryLayout layout;
    layout.build(scene);
    const MemoryImage image =
        buildImage(scene, layout, selection.scene.empty() ? file.path().string() : selection.scene);
    result.imageBytes = layout.totalBytes();

    // Step: the model's answer per ray, with the bytes, sectors and checksum of its fetches.
    PolicySide side(rays);
    std::vector<gpucheck::RayOut> expected(rays.size());
    std::uint64_t fetchSectors = 0, fetchBytes = 0;
    std::uint32_t maxStack = 0;
    for (std::size_t i = 0; i < rays.size(); ++i) {
        RayTraversal traversal;
        traversal.begin(scene, simRays[i]);
        StepInfo st;
        gpucheck::RayOut& e = expected[i];
        std::uint32_t checksum = 0x811c9dc5u;
        while (!traversal.finished()) {
            traversal.step(side, static_cast<std::uint32_t>(i), st);
            const MemoryRange range = fetchRange(st, scene, layout);
            e.fetchBytes += range.bytes;
            e.fetchSectors +=
                static_cast<std::uint32_t>(((range.address + range.bytes - 1) >> 5) - (range.address >> 5) + 1);
            for (std::uint64_t a = range.address; a < range.address + range.bytes; a += 4)
                checksum = (checksum ^ image.words[a >> 2]) * 0x01000193u;
        }
        const ModelHit& hit = traversal.hit();
        const TraversalCounters& c = traversal.counters();
        e.t = hit.t;
        e.b1 = hit.b1;
        e.b2 = hit.b2;
        e.hit = hit.hit ? 1u : 0u;
        e.instance = hit.instanceIndex;
        e.geometry = hit.geometryIndex;
        e.primitive = hit.primitiveIndex;
        e.steps = c.steps;
        e.nodeVisits = c.nodeVisits;
        e.leafVisits = c.leafVisits;
        e.triangleTests = c.triangleTests;
        e.instanceTransitions = c.instanceTransitions;
        e.maxStackDepth = c.maxStackDepth;
        e.checksum = checksum;
        fetchSectors += e.fetchSectors;
        fetchBytes += e.fetchBytes;
        maxStack = std::max(maxStack, c.maxStackDepth);
        // The recording's hit is the model's (same scene, same rays, same verdicts).
        const RayRecord& r = *records[i];
        const bool recordedHit = (r.flags & RayRecord::kHit) != 0;
        if (recordedHit != hit.hit ||
            (hit.hit &&
             (std::bit_cast<std::uint32_t>(r.hitT) != std::bit_cast<std::uint32_t>(hit.t) ||
              r.instance != hit.instanceIndex || r.geometry != hit.geometryIndex || r.primitive != hit.primitiveIndex)))
            throw InputError(file.path().string(), "ray " + std::to_string(i) +
                                                       " of the selection hits otherwise on this scene than recorded "
                                                       "(another scene, frame or BVH configuration?)");
    }
    result.rays = rays.size();

    // Step: the timing model on the same rays as one launch, one thread per ray, from a cold start.
    RtCore core(config, scene);
    core.reset();
    std::vector<std::uint32_t> threads(rays.size());
    std::iota(threads.begin(), threads.end(), 0u);
    std::vector<SimRayResult> results(rays.size());
    core.runLaunch(simRays, threads, static_cast<std::uint32_t>(rays.size()), side, results);
    const nlohmann::json stats = core.statsJson();
    const double n = double(rays.size());
    const nlohmann::json& l1 = stats["cache"];
    const nlohmann::json& l2 = stats["l2"];
    const std::uint64_t l1Accesses = l1["accesses"], l1Hits = l1["hits"], l1Pending = l1["pendingHits"];
    const std::uint64_t l2Accesses = l2["accesses"], l2Hits = l2["hits"], l2Pending = l2["pendingHits"];
    const std::uint64_t dramBytes = stats["dram"]["readBytes"];
    nlohmann::json& m = result.model;
    m["format"] = gpucheck::kFormatVersion;
    m["label"] = selection.label;
    m["recording"] = file.path().string();
    m["frame"] = info.frame;
    m["rays"] = rays.size();
    m["left out"] = {{"invalidRays", result.invalidRays},
                     {"otherVerdicts", result.otherVerdicts},
                     {"beyondMaxRays", result.beyondMaxRays}};
    m["policies"] = {
        {"commitAll", std::count_if(rays.begin(), rays.end(),
                                    [](const gpucheck::RayIn& r) { return r.policy == gpucheck::kCommitAll; })},
        {"firstHit", std::count_if(rays.begin(), rays.end(),
                                   [](const gpucheck::RayIn& r) { return r.policy == gpucheck::kFirstHit; })}};
    m["imageBytes"] = result.imageBytes;
    m["maxStackDepth"] = maxStack;
    m["fetch"] = {{"bytes", fetchBytes}, {"sectors", fetchSectors}, {"sectorsPerRay", double(fetchSectors) / n}};
    m["predicted"] = {{"cycles", core.cycle()},
                      {"l1",
                       {{"accesses", l1Accesses},
                        {"hits", l1Hits},
                        {"pendingHits", l1Pending},
                        {"misses", l1["misses"]},
                        {"lineBytes", config.cache.lineBytes},
                        {"missBytesPerRay", double(std::uint64_t(l1["misses"]) * config.cache.fillBytes()) / n},
                        {"hitRate", l1Accesses ? double(l1Hits) / double(l1Accesses) : 0.0},
                        {"hitRateWithoutPending", l1Accesses ? double(l1Hits - l1Pending) / double(l1Accesses) : 0.0}}},
                      {"l2",
                       {{"accesses", l2Accesses},
                        {"hits", l2Hits},
                        {"pendingHits", l2Pending},
                        {"misses", l2["misses"]},
                        {"lineBytes", config.l2.lineBytes},
                        {"hitRate", l2Accesses ? double(l2Hits) / double(l2Accesses) : 0.0},
                        {"hitRateWithoutPending", l2Accesses ? double(l2Hits - l2Pending) / double(l2Accesses) : 0.0}}},
                      {"dram", {{"readBytes", dramBytes}, {"bytesPerRay", double(dramBytes) / n}}}};
    m["config"] = stats["config"];

    // Step: the files.
    std::error_code ec;
    std::filesystem::create_directories(out, ec);
    if (ec || !std::filesystem::is_directory(out)) throw InputError(out.string(), "cannot create output directory");
    std::vector<unsigned char> tables(image.meshes.size() * sizeof(gpucheck::MeshInfo) +
                                      image.instances.size() * sizeof(gpucheck::InstanceInfo));
    std::memcpy(tables.data(), image.meshes.data(), image.meshes.size() * sizeof(gpucheck::MeshInfo));
    std::memcpy(tables.data() + image.meshes.size() * sizeof(gpucheck::MeshInfo), image.instances.data(),
                image.instances.size() * sizeof(gpucheck::InstanceInfo));
    // One id in the three files: a set written partly over an older export is refused by the reader.
    Fnv64 id;
    id.add(image.words.data(), image.words.size() * 4);
    id.add(rays.data(), rays.size() * sizeof(gpucheck::RayIn));
    id.add(expected.data(), expected.size() * sizeof(gpucheck::RayOut));
    const std::uint32_t exportId = static_cast<std::uint32_t>(id.value() ^ (id.value() >> 32));
    gpucheck::SceneHeader header = image.header;
    header.exportId = exportId;
    writeBinary(out / "scene.bin", &header, sizeof header, image.words, tables.data(), tables.size());
    gpucheck::RaysHeader rh{};
    std::memcpy(rh.magic, "RTLGCRAY", 8);
    rh.version = gpucheck::kFormatVersion;
    rh.rayCount = static_cast<std::uint32_t>(rays.size());
    rh.exportId = exportId;
    writeBinary(out / "rays.bin", &rh, sizeof rh, rays);
    gpucheck::ExpectedHeader eh{};
    std::memcpy(eh.magic, "RTLGCEXP", 8);
    eh.version = gpucheck::kFormatVersion;
    eh.rayCount = static_cast<std::uint32_t>(rays.size());
    eh.exportId = exportId;
    writeBinary(out / "expected.bin", &eh, sizeof eh, expected);
    writeTextFileAtomically(out / "model.json", m.dump(2) + "\n");
    return result;
}

}  // namespace rtlab::study
