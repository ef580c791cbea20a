#include <rtlab/study/ray_trace_file.hpp>

#include <rtlab/core/error.hpp>
#include <rtlab/rtcore_sim/rtcore.hpp>
#include <rtlab/session/frame_options.hpp>

#include <algorithm>
#include <bit>
#include <cstring>
#include <fstream>
#include <stdexcept>
#include <system_error>

namespace rtlab::study {

static_assert(std::endian::native == std::endian::little, "ray-trace files are little-endian");

void Fnv64::add(const void* data, std::size_t bytes) {
    const auto* p = static_cast<const unsigned char*>(data);
    std::size_t i = 0;
    for (; i + 8 <= bytes; i += 8) {
        std::uint64_t word;
        std::memcpy(&word, p + i, 8);
        hash_ = (hash_ ^ word) * 0x100000001b3ull;
    }
    if (i < bytes) {
        std::uint64_t word = 0;
        std::memcpy(&word, p + i, bytes - i);
        hash_ = (hash_ ^ word) * 0x100000001b3ull;
    }
}

std::uint64_t sceneFingerprint(const ecs::SceneSnapshot& scene) {
    Fnv64 h;
    const std::uint64_t meshCount = scene.meshes ? scene.meshes->size() : 0;
    h.addValue(meshCount);
    for (std::uint64_t m = 0; m < meshCount; ++m) {
        const ecs::MeshAsset& mesh = (*scene.meshes)[m];
        h.addValue(std::uint64_t(mesh.geometries.size()));
        for (const ecs::Geometry& g : mesh.geometries) {
            h.addValue(std::uint64_t(g.positions.size()));
            h.add(g.positions.data(), g.positions.size() * sizeof(vec3));
            h.addValue(std::uint64_t(g.indices.size()));
            h.add(g.indices.data(), g.indices.size() * sizeof(std::uint32_t));
            h.addValue(std::uint64_t(g.proceduralBoxes.size()));
            for (const Aabb& b : g.proceduralBoxes) {
                h.addValue(b.lo);
                h.addValue(b.hi);
            }
        }
    }
    h.addValue(std::uint64_t(scene.instances.size()));
    for (const ecs::InstanceSnapshot& inst : scene.instances) {
        h.addValue(inst.mesh);
        h.add(&inst.worldFromObject[0][0], sizeof(float) * 16);
        const std::uint32_t small[4] = {inst.mask, inst.flags, inst.instanceId, inst.hitGroupOffset};
        h.add(small, sizeof small);
    }
    return h.value();
}

// ---- writing ---------------------------------------------------------------------

RayTraceWriter::RayTraceWriter(std::filesystem::path path) : path_(std::move(path)) {
    temporary_ = path_;
    temporary_ += ".tmp";
    file_ = std::fopen(temporary_.c_str(), "wb");
    if (!file_) throw InputError(temporary_.string(), "cannot create the ray-trace file");
    const RayTraceHeader placeholder{};
    write(&placeholder, sizeof placeholder);
    bodyBytes_ = 0;
    checksum_ = Fnv64{};
}

RayTraceWriter::~RayTraceWriter() {
    if (file_) {
        std::fclose(file_);
        std::error_code ec;
        std::filesystem::remove(temporary_, ec);
    }
}

void RayTraceWriter::write(const void* data, std::size_t bytes) {
    if (bytes == 0) return;  // data may be an empty vector's null pointer, which fwrite must not get
    if (std::fwrite(data, 1, bytes, file_) != bytes)
        throw std::runtime_error(temporary_.string() + ": write failed (disk full?)");
    bodyBytes_ += bytes;
}

void RayTraceWriter::append(const tracer::TraceArgs& args, std::uint32_t depth, const tracer::RayDesc* rays,
                            const bool* active, const tracer::CommittedHit* hits, std::size_t count,
                            const BatchLaunch& launch) {
    if (count > kMaxBatchLanes)
        throw std::invalid_argument("RayTraceWriter::append: a call of " + std::to_string(count) +
                                    " lanes, more than the format's " + std::to_string(kMaxBatchLanes));
    scratch_.clear();
    for (std::size_t i = 0; i < count; ++i) {
        if (!active[i]) continue;
        RayRecord r{};
        const tracer::RayDesc& ray = rays[i];
        std::memcpy(r.origin, &ray.origin, sizeof r.origin);
        r.tMin = ray.tMin;
        std::memcpy(r.direction, &ray.direction, sizeof r.direction);
        r.tMax = ray.tMax;
        r.hitT = kInfinity;
        r.lane = static_cast<std::uint32_t>(i);
        const tracer::CommittedHit& h = hits[i];
        if (h.hit) {
            r.flags = RayRecord::kHit;
            r.hitT = h.t;
            r.hitU = h.attributes.values[0];
            r.hitV = h.attributes.values[1];
            r.instance = h.instanceIndex;
            r.primitive = h.primitiveIndex;
            r.hitGroupRecord = h.hitGroupRecord;
            r.geometry = static_cast<std::uint16_t>(h.geometryIndex);
            r.hitKind = static_cast<std::uint8_t>(h.hitKind);
        }
        scratch_.push_back(r);
    }
    const BatchRecord batch{kBatchTag,
                            static_cast<std::uint32_t>(count),
                            static_cast<std::uint32_t>(scratch_.size()),
                            depth,
                            args.rayFlags,
                            args.instanceInclusionMask,
                            static_cast<std::uint16_t>(args.rayContribution),
                            static_cast<std::uint16_t>(args.multiplier),
                            args.missIndex};
    checksum_.add(&batch, sizeof batch);
    write(&batch, sizeof batch);
    checksum_.add(scratch_.data(), scratch_.size() * sizeof(RayRecord));
    write(scratch_.data(), scratch_.size() * sizeof(RayRecord));
    if (launch.parents.size() != scratch_.size() ||
        (!launch.verdictCounts.empty() && launch.verdictCounts.size() != scratch_.size()))
        throw std::logic_error("RayTraceWriter::append: one parent and verdict count per active lane");
    std::uint64_t words = 0;
    links_.resize(scratch_.size());
    for (std::size_t i = 0; i < scratch_.size(); ++i) {
        links_[i].parent = launch.parents[i];
        links_[i].verdicts = launch.verdictCounts.empty() ? 0 : launch.verdictCounts[i];
        words += links_[i].verdicts;
    }
    if (words != launch.verdictWords.size() || words > UINT32_MAX)
        throw std::logic_error("RayTraceWriter::append: verdict counts do not add up to the words");
    const BatchLaunchRecord where{launch.launch, launch.launchThreads, launch.threadBase,
                                  static_cast<std::uint32_t>(words)};
    checksum_.add(&where, sizeof where);
    write(&where, sizeof where);
    checksum_.add(links_.data(), links_.size() * sizeof(RayLinkRecord));
    write(links_.data(), links_.size() * sizeof(RayLinkRecord));
    // Verdict words, zero-padded to 8 bytes (the checksum reads 8-byte words).
    std::vector<std::uint32_t> padded(launch.verdictWords.begin(), launch.verdictWords.end());
    if (padded.size() % 2) padded.push_back(0);
    checksum_.add(padded.data(), padded.size() * sizeof(std::uint32_t));
    write(padded.data(), padded.size() * sizeof(std::uint32_t));
    launches_ = std::max(launches_, launch.launch + 1);
    ++batches_;
    lanes_ += count;
    rays_ += scratch_.size();
}

void RayTraceWriter::finish(const RayTraceInfo& info) {
    RayTraceHeader h{};
    std::memcpy(h.magic, kRayTraceMagic, sizeof h.magic);
    h.version = kRayTraceVersion;
    h.headerBytes = sizeof(RayTraceHeader);
    h.sceneFingerprint = info.sceneFingerprint;
    h.batchCount = batches_;
    h.laneCount = lanes_;
    h.rayCount = rays_;
    h.bodyBytes = bodyBytes_;
    h.bodyChecksum = checksum_.value();
    h.frame = info.frame;
    h.rayTypeCount = info.rayTypeCount;
    h.hitGroupCount = info.hitGroupCount;
    h.backend = static_cast<std::uint32_t>(info.backend);
    h.flags =
        (info.anyHitShaders ? RayTraceHeader::kAnyHitShaders : 0) | (info.verdicts ? RayTraceHeader::kVerdicts : 0);
    h.launchCount = launches_;
    h.instanceCount = info.instanceCount;
    h.uniqueTriangles = info.uniqueTriangles;
    const bool ok =
        std::fseek(file_, 0, SEEK_SET) == 0 && std::fwrite(&h, sizeof h, 1, file_) == 1 && std::fflush(file_) == 0;
    const bool closed = std::fclose(file_) == 0;
    file_ = nullptr;
    std::error_code ec;
    if (!ok || !closed) {
        std::filesystem::remove(temporary_, ec);
        throw std::runtime_error(temporary_.string() + ": write failed (disk full?)");
    }
    std::filesystem::rename(temporary_, path_, ec);
    if (ec) throw std::runtime_error(path_.string() + ": cannot rename the finished ray-trace file: " + ec.message());
}

// ---- reading ---------------------------------------------------------------------

RayTraceFile RayTraceFile::read(const std::filesystem::path& path) {
    RayTraceFile f;
    f.path_ = path;
    const std::string where = path.string();
    std::ifstream in(path, std::ios::binary);
    if (!in) throw InputError(where, "cannot open the ray-trace file");
    in.seekg(0, std::ios::end);
    const std::streamoff size = in.tellg();
    in.seekg(0);
    if (size < std::streamoff(sizeof(RayTraceHeader)))
        throw InputError(where, "not a ray-trace file (" + std::to_string(size) + " bytes, shorter than the header)");
    // Step: the header.
    in.read(reinterpret_cast<char*>(&f.header_), sizeof f.header_);
    const RayTraceHeader& h = f.header_;
    if (std::memcmp(h.magic, kRayTraceMagic, sizeof h.magic) != 0)
        throw InputError(where, "not a ray-trace file (bad magic; docs/ray-trace-format.md)");
    if (h.version < kRayTraceOldestVersion || h.version > kRayTraceVersion)
        throw InputError(where, "ray-trace format version " + std::to_string(h.version) +
                                    ", this rtlab reads versions " + std::to_string(kRayTraceOldestVersion) + " to " +
                                    std::to_string(kRayTraceVersion));
    const bool v2 = h.version >= 2;
    if (h.headerBytes != sizeof(RayTraceHeader)) throw InputError(where, "corrupt header (header size)");
    // Version 2 adds per batch 16 bytes and per ray 8, plus the verdict words.
    const std::uint64_t least = h.batchCount * (sizeof(BatchRecord) + (v2 ? sizeof(BatchLaunchRecord) : 0)) +
                                h.rayCount * (sizeof(RayRecord) + (v2 ? sizeof(RayLinkRecord) : 0));
    if ((v2 ? h.bodyBytes < least : h.bodyBytes != least) || h.batchCount > (std::uint64_t(1) << 40) ||
        h.rayCount > (std::uint64_t(1) << 40) || h.rayCount > h.laneCount ||
        (!v2 && (h.flags & RayTraceHeader::kVerdicts)))
        throw InputError(where, "corrupt header (batch and ray counts do not add up to the body size)");
    if (std::uint64_t(size) - sizeof(RayTraceHeader) != h.bodyBytes)
        throw InputError(where, "truncated or padded: the header announces " +
                                    std::to_string(h.bodyBytes + sizeof(RayTraceHeader)) + " bytes, the file has " +
                                    std::to_string(size));
    if (h.laneCount > kMaxBatchLanes + kLanesPerBodyByte * h.bodyBytes)
        throw InputError(where, "corrupt header (" + std::to_string(h.laneCount) + " lanes, more than " +
                                    std::to_string(kMaxBatchLanes) + " + " + std::to_string(kLanesPerBodyByte) +
                                    " per body byte)");
    if (h.rayTypeCount == 0 || h.rayTypeCount > 16 || h.backend > 1)
        throw InputError(where, "corrupt header (ray-type count or back end)");
    // A replay advances the scene frame by frame to the recorded one.
    if (h.frame >= std::uint32_t(session::kMaxFrames))
        throw InputError(where, "corrupt header (frame " + std::to_string(h.frame) + "; a render makes at most " +
                                    std::to_string(session::kMaxFrames) + " frames)");
    // Step: the body, checksummed, then split into batches.
    f.storage_.resize((h.bodyBytes + 7) / 8);
    in.read(reinterpret_cast<char*>(f.storage_.data()), std::streamsize(h.bodyBytes));
    if (!in) throw InputError(where, "read failed");
    Fnv64 sum;
    sum.add(f.storage_.data(), h.bodyBytes);
    if (sum.value() != h.bodyChecksum)
        throw InputError(where, "corrupt: the body's checksum does not match the header");
    const auto* bytes = reinterpret_cast<const unsigned char*>(f.storage_.data());
    std::uint64_t offset = 0, lanes = 0, rays = 0, launchRays = 0;
    std::uint64_t launchThreads = 0, openLaunchThreads = 0;  // all launches' threads; the open launch's
    f.batches_.reserve(h.batchCount);
    for (std::uint64_t b = 0; b < h.batchCount; ++b) {
        const std::string batchName = "batch " + std::to_string(b);
        if (offset + sizeof(BatchRecord) > h.bodyBytes)
            throw InputError(where, "corrupt: " + batchName + " runs past the end");
        const auto* record = reinterpret_cast<const BatchRecord*>(bytes + offset);
        if (record->tag != kBatchTag) throw InputError(where, "corrupt: " + batchName + " has no batch tag");
        if (record->rays > record->lanes)
            throw InputError(where, "corrupt: " + batchName + " has more rays than lanes");
        if (record->lanes > kMaxBatchLanes)
            throw InputError(where, "corrupt: " + batchName + " has " + std::to_string(record->lanes) +
                                        " lanes, more than the format's " + std::to_string(kMaxBatchLanes));
        offset += sizeof(BatchRecord);
        if (offset + std::uint64_t(record->rays) * sizeof(RayRecord) > h.bodyBytes)
            throw InputError(where, "corrupt: " + batchName + " runs past the end");
        const auto* records = reinterpret_cast<const RayRecord*>(bytes + offset);
        const std::span<const RayRecord> span(records, record->rays);
        // Lanes strictly increasing and inside the call.
        for (std::size_t i = 0; i < span.size(); ++i)
            if (span[i].lane >= record->lanes || (i > 0 && span[i].lane <= span[i - 1].lane))
                throw InputError(where, "corrupt: " + batchName + " has a ray on lane " + std::to_string(span[i].lane) +
                                            " out of order or beyond its " + std::to_string(record->lanes) + " lanes");
        offset += std::uint64_t(record->rays) * sizeof(RayRecord);
        Batch batch{record, span, nullptr, {}, {}};
        if (v2) {
            const std::uint64_t linkBytes = std::uint64_t(record->rays) * sizeof(RayLinkRecord);
            if (offset + sizeof(BatchLaunchRecord) + linkBytes > h.bodyBytes)
                throw InputError(where, "corrupt: " + batchName + " runs past the end");
            batch.launch = reinterpret_cast<const BatchLaunchRecord*>(bytes + offset);
            offset += sizeof(BatchLaunchRecord);
            batch.links = std::span(reinterpret_cast<const RayLinkRecord*>(bytes + offset), record->rays);
            offset += linkBytes;
            const std::uint64_t words = batch.launch->verdictWords;
            const std::uint64_t wordBytes = (words + (words & 1)) * sizeof(std::uint32_t);
            if (offset + wordBytes > h.bodyBytes)
                throw InputError(where, "corrupt: " + batchName + " runs past the end");
            batch.verdicts = std::span(reinterpret_cast<const std::uint32_t*>(bytes + offset), words);
            offset += wordBytes;
            if (batch.launch->launch >= h.launchCount || batch.launch->launchThreads == 0 ||
                batch.launch->launchThreads > rtcore_sim::kMaxLaunchThreads ||
                std::uint64_t(batch.launch->threadBase) + record->lanes > batch.launch->launchThreads)
                throw InputError(where, "corrupt: " + batchName + " lies outside its launch's threads");
            if (!f.batches_.empty() && f.batches_.back().launch->launch > batch.launch->launch)
                throw InputError(where, "corrupt: " + batchName + "'s launch is out of order");
            if (f.batches_.empty() || f.batches_.back().launch->launch != batch.launch->launch) {
                launchRays = 0;
                launchThreads += openLaunchThreads;
                openLaunchThreads = 0;
            }
            openLaunchThreads = std::max<std::uint64_t>(openLaunchThreads, batch.launch->launchThreads);
            // Links: parents earlier in the launch, verdict counts adding up.
            std::uint64_t sum = 0;
            for (const RayLinkRecord& l : batch.links) {
                if (l.parent != RayLinkRecord::kNoParent && l.parent >= launchRays)
                    throw InputError(where,
                                     "corrupt: " + batchName + " has a ray whose parent is not earlier in its launch");
                sum += l.verdicts;
                ++launchRays;
            }
            if (sum != words) throw InputError(where, "corrupt: " + batchName + "'s verdict counts do not add up");
            if (!(h.flags & RayTraceHeader::kVerdicts) && words != 0)
                throw InputError(where, "corrupt: " + batchName + " has verdicts the header does not announce");
        }
        f.batches_.push_back(batch);
        lanes += record->lanes;
        rays += record->rays;
    }
    if (offset != h.bodyBytes || lanes != h.laneCount || rays != h.rayCount)
        throw InputError(where, "corrupt: the batches do not match the header's counts");
    // A replay's model allocates and walks every thread of every launch.
    launchThreads += openLaunchThreads;
    if (launchThreads > rtcore_sim::kMaxLaunchThreads + kLaunchThreadsPerBodyByte * h.bodyBytes)
        throw InputError(where, "corrupt: the launches declare " + std::to_string(launchThreads) +
                                    " threads in all, more than " + std::to_string(rtcore_sim::kMaxLaunchThreads) +
                                    " + " + std::to_string(kLaunchThreadsPerBodyByte) + " per body byte");
    return f;
}

tracer::TraceArgs RayTraceFile::Batch::args() const {
    tracer::TraceArgs a;
    a.rayFlags = record->rayFlags;
    a.instanceInclusionMask = record->instanceInclusionMask;
    a.rayContribution = record->rayContribution;
    a.multiplier = record->multiplier;
    a.missIndex = record->missIndex;
    return a;
}

RayTraceInfo RayTraceFile::info() const {
    RayTraceInfo i;
    i.frame = header_.frame;
    i.sceneFingerprint = header_.sceneFingerprint;
    i.rayTypeCount = header_.rayTypeCount;
    i.hitGroupCount = header_.hitGroupCount;
    i.backend = static_cast<RecordedBackend>(header_.backend);
    i.anyHitShaders = (header_.flags & RayTraceHeader::kAnyHitShaders) != 0;
    i.instanceCount = header_.instanceCount;
    i.uniqueTriangles = header_.uniqueTriangles;
    i.version = header_.version;
    i.launches = header_.version >= 2 ? header_.launchCount : 0;
    i.verdicts = (header_.flags & RayTraceHeader::kVerdicts) != 0;
    return i;
}

tracer::RayDesc rayOf(const RayRecord& r) {
    tracer::RayDesc d;
    std::memcpy(&d.origin, r.origin, sizeof r.origin);
    d.tMin = r.tMin;
    std::memcpy(&d.direction, r.direction, sizeof r.direction);
    d.tMax = r.tMax;
    return d;
}

tracer::CommittedHit hitOf(const RayRecord& r) {
    tracer::CommittedHit h;
    if (!(r.flags & RayRecord::kHit)) return h;
    h.hit = true;
    h.t = r.hitT;
    h.instanceIndex = r.instance;
    h.geometryIndex = r.geometry;
    h.primitiveIndex = r.primitive;
    h.hitKind = r.hitKind;
    h.hitGroupRecord = r.hitGroupRecord;
    h.attributes.values[0] = r.hitU;
    h.attributes.values[1] = r.hitV;
    return h;
}

}  // namespace rtlab::study
