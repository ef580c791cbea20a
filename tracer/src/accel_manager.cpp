#include <rtlab/core/timer.hpp>
#include <rtlab/tracer/accel_manager.hpp>
#include <rtlab/tracer/conservative_bounds.hpp>
#include <rtlab/tracer/instance_transform.hpp>
#include <rtlab/tracer/dxr.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>

namespace rtlab::tracer {
namespace {

void embreeErrorHandler(void*, RTCError code, const char* message) {
    // Embree reports API misuse and out-of-memory here; surface them loudly.
    throw std::runtime_error("embree error " + std::to_string(static_cast<int>(code)) + ": " +
                             (message ? message : "(no message)"));
}

void uploadVertices(RTCGeometry geom, const ecs::Geometry& g, bool allocate) {
    float* v = allocate
                   ? static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                                 sizeof(float) * 3, g.positions.size()))
                   : static_cast<float*>(rtcGetGeometryBufferData(geom, RTC_BUFFER_TYPE_VERTEX, 0));
    std::memcpy(v, g.positions.data(), g.positions.size() * sizeof(vec3));
    if (!allocate) rtcUpdateGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0);
}

// Refit quality estimate. Triangles ordered along a Morton curve of their
// centroids and cut into fixed clusters of kClusterSize are spatially tight
// groups, like a BVH's lower nodes. The SAH-style cost
//   C(order) = sum over clusters (area(cluster bounds) * triangles) / area(all bounds)
// of the build-time order is what a refit keeps; C of a fresh Morton order
// of the current positions is what a rebuild would get. Their ratio says how
// much a rebuild would gain (1 = nothing).
constexpr std::size_t kClusterSize = 32;

std::uint32_t spreadBits10(std::uint32_t v) {
    v &= 0x3ffu;
    v = (v | (v << 16)) & 0x030000ffu;
    v = (v | (v << 8)) & 0x0300f00fu;
    v = (v | (v << 4)) & 0x030c30c3u;
    v = (v | (v << 2)) & 0x09249249u;
    return v;
}

std::vector<std::uint32_t> mortonTriangleOrder(const ecs::Geometry& g) {
    const std::size_t n = g.triangleCount();
    Aabb bounds;
    for (const vec3& p : g.positions) bounds.extend(p);
    const vec3 scale = 1023.f / glm::max(bounds.extent(), vec3(1e-30f));
    // Coordinates near FLT_MAX overflow the centroid or the extent (inf -
    // inf is NaN, which has no integer value): such a cell is 0.
    const auto cell = [](float v) { return v > 0.f ? static_cast<std::uint32_t>(std::min(v, 1023.f)) : 0u; };
    std::vector<std::pair<std::uint32_t, std::uint32_t>> keyed(n);
    for (std::size_t t = 0; t < n; ++t) {
        const vec3 c =
            (g.positions[g.indices[3 * t]] + g.positions[g.indices[3 * t + 1]] + g.positions[g.indices[3 * t + 2]]) /
            3.f;
        const vec3 q = (c - bounds.lo) * scale;
        keyed[t] = {spreadBits10(cell(q.x)) | (spreadBits10(cell(q.y)) << 1) | (spreadBits10(cell(q.z)) << 2),
                    static_cast<std::uint32_t>(t)};
    }
    std::sort(keyed.begin(), keyed.end());
    std::vector<std::uint32_t> order(n);
    for (std::size_t i = 0; i < n; ++i) order[i] = keyed[i].second;
    return order;
}

double clusterCost(const ecs::Geometry& g, const std::vector<std::uint32_t>& order) {
    Aabb all;
    double sum = 0.0;
    for (std::size_t c = 0; c < order.size(); c += kClusterSize) {
        Aabb box;
        const std::size_t end = std::min(order.size(), c + kClusterSize);
        for (std::size_t k = c; k < end; ++k)
            for (int v = 0; v < 3; ++v) box.extend(g.positions[g.indices[3 * order[k] + v]]);
        sum += double(box.surfaceArea()) * double(end - c);
        all.extend(box);
    }
    const double rootArea = all.surfaceArea();
    return rootArea > 0.0 ? sum / rootArea : 0.0;
}

// Clusters of up to kClusterTriangles triangles, grown along the Morton
// curve `order`: a cluster starts at the first unassigned triangle and takes,
// among the next kClusterLookAhead unassigned ones, the triangle that grows
// its box least, while an SAH-style cost says merging pays: rays entering
// the merged box pay one callback (kCallbackCost triangle tests) and one
// triangle more, rays entering the two boxes apart pay a callback each and
// their own triangles. So large triangles (walls, floors) are not lumped
// into one box that every ray enters, and the look-ahead finds the
// neighbours a Z-curve puts a few places away. Measured (make bench,
// docs/acceleration-structures.md): the old rule (next Morton triangle only,
// while the box's area stays below the sum of the triangles' boxes' areas)
// made clusters of 1.6 triangles on the showcase and traced its bounce rays
// at 0.76 of native Embree; this one at 0.83-0.93 over several runs, with
// about 106 bytes per terrain triangle (Embree's BVH 55 plus the packed clusters 51).
// Triangles with a non-finite vertex are left out (Embree and the RT-core
// model skip them too).
constexpr std::size_t kClusterLookAhead = 16;
constexpr float kCallbackCost = 8.f;  // an Embree callback, in triangle tests

void buildClusters(WatertightTriangles& data, const ecs::Geometry& g, const std::vector<std::uint32_t>& order) {
    data.clusters.clear();
    data.clusters.reserve((order.size() + kClusterTriangles - 1) / kClusterTriangles);
    // Step: the finite triangles in Morton order, with their boxes.
    std::vector<std::uint32_t> pending;
    std::vector<Aabb> boxes;
    pending.reserve(order.size());
    boxes.reserve(order.size());
    for (const std::uint32_t t : order) {
        const vec3& p0 = g.positions[g.indices[3 * t]];
        const vec3& p1 = g.positions[g.indices[3 * t + 1]];
        const vec3& p2 = g.positions[g.indices[3 * t + 2]];
        if (!isFinite(p0) || !isFinite(p1) || !isFinite(p2)) continue;
        Aabb box;
        box.extend(p0);
        box.extend(p1);
        box.extend(p2);
        pending.push_back(t);
        boxes.push_back(box);
    }
    std::vector<std::uint8_t> assigned(pending.size(), 0);
    auto add = [&](TriangleCluster& c, std::size_t k) {
        const std::uint32_t t = pending[k];
        c.primitive[c.count] = t;
        c.set(static_cast<int>(c.count), g.positions[g.indices[3 * t]], g.positions[g.indices[3 * t + 1]],
              g.positions[g.indices[3 * t + 2]]);
        ++c.count;
        assigned[k] = 1;
    };
    std::size_t head = 0;
    while (true) {
        while (head < pending.size() && assigned[head]) ++head;
        if (head == pending.size()) break;
        // Step: a new cluster from the first unassigned triangle.
        TriangleCluster& c = data.clusters.emplace_back();
        Aabb clusterBox = boxes[head];
        float clusterArea = clusterBox.surfaceArea();
        add(c, head);
        // Step: the next unassigned triangles within the look-ahead.
        std::size_t candidates[kClusterLookAhead];
        std::size_t candidateCount = 0;
        for (std::size_t k = head + 1; k < pending.size() && candidateCount < kClusterLookAhead; ++k)
            if (!assigned[k]) candidates[candidateCount++] = k;
        // Step: grow by the candidate that enlarges the box least, while the rule holds.
        while (c.count < static_cast<std::uint32_t>(kClusterTriangles)) {
            std::size_t best = pending.size();
            float bestArea = 0.f;
            for (std::size_t n = 0; n < candidateCount; ++n) {
                const std::size_t k = candidates[n];
                if (assigned[k]) continue;
                Aabb merged = clusterBox;
                merged.extend(boxes[k]);
                const float area = merged.surfaceArea();
                // The SAH-style rule: rays entering the merged box pay one
                // callback and one more triangle; kept apart, the rays entering
                // each box pay a callback and their own triangles.
                const float members = static_cast<float>(c.count);
                const float mergedCost = area * (kCallbackCost + members + 1.f);
                const float apartCost =
                    clusterArea * (kCallbackCost + members) + boxes[k].surfaceArea() * (kCallbackCost + 1.f);
                if (mergedCost > apartCost) continue;
                if (best == pending.size() || area < bestArea) best = k, bestArea = area;
            }
            if (best == pending.size()) break;
            clusterBox.extend(boxes[best]);
            clusterArea = clusterBox.surfaceArea();
            add(c, best);
        }
    }
}

// After a refit: the same triangles per cluster, their new vertices.
void refreshClusterVertices(WatertightTriangles& data, const ecs::Geometry& g) {
    for (TriangleCluster& c : data.clusters)
        for (std::uint32_t s = 0; s < c.count; ++s) {
            const std::uint32_t t = c.primitive[s];
            c.set(static_cast<int>(s), g.positions[g.indices[3 * t]], g.positions[g.indices[3 * t + 1]],
                  g.positions[g.indices[3 * t + 2]]);
        }
}

// The power of two at or above x (0 for x <= 0): paddings change in steps,
// so that slowly growing ray origins do not re-pad a BLAS every frame.
float quantizePaddingUp(float x) {
    if (!(x > 0.f)) return 0.f;
    int exponent = 0;
    std::frexp(x, &exponent);
    return std::ldexp(1.f, exponent);
}

float objectMagnitudeOf(const ecs::MeshAsset& mesh) {
    float m = 0.f;
    for (const ecs::Geometry& g : mesh.geometries) {
        for (const vec3& p : g.positions)
            if (isFinite(p)) m = std::max(m, maxAbsCoordinate(p));
        for (const Aabb& b : g.proceduralBoxes)
            if (isFinite(b.lo) && isFinite(b.hi)) m = std::max(m, maxAbsCoordinate(b));
    }
    return m;
}

}  // namespace

void watertightBoundsCallback(const RTCBoundsFunctionArguments* args) {
    const auto& data = *static_cast<const WatertightTriangles*>(args->geometryUserPtr);
    const TriangleCluster& c = data.clusters[args->primID];
    Aabb box;
    for (std::uint32_t s = 0; s < c.count; ++s)
        for (int k = 0; k < 3; ++k) {
            const vec3 p = c.vertex(static_cast<int>(s), k);
            if (isFinite(p)) box.extend(p);
        }
    // Padding: Embree's user-geometry and instance BVHs use the non-robust box test.
    box.lo -= vec3(data.padding);
    box.hi += vec3(data.padding);
    storeEmbreeBounds(args->bounds_o, box);
}

void AccelManager::updateConservativePadding(const ecs::SceneSnapshot& scene,
                                             const std::vector<std::uint8_t>& changed) {
    const auto& meshes = *scene.meshes;
    // Step: the largest |object coordinate| of every mesh (recomputed only for changed ones).
    if (objectMagnitude_.size() < meshes.size()) objectMagnitude_.resize(meshes.size(), -1.f);
    for (std::size_t id = 0; id < meshes.size(); ++id)
        if (changed[id] || objectMagnitude_[id] < 0.f) objectMagnitude_[id] = objectMagnitudeOf(meshes[id]);
    // Step: a bound on every ray origin's |world coordinate|: the instances'
    // world boxes, the camera, and what the caller declared.
    const vec3 cameraPosition = vec3(scene.camera.worldFromCamera[3]);
    double originBound = std::max<double>(options_.rayOriginBound, maxAbsCoordinate(cameraPosition));
    std::vector<double> worldToObjectGain(meshes.size(), 1.0), conditioning(meshes.size(), 1.0);
    for (const ecs::InstanceSnapshot& inst : scene.instances) {
        if (inst.mesh >= meshes.size()) continue;
        const double objectToWorld = maxNormGain(inst.worldFromObject);
        const double worldToObject = maxNormGain(objectFromWorldOf(inst.worldFromObject));
        originBound = std::max(originBound, double(maxAbsCoordinate(vec3(inst.worldFromObject[3]))) +
                                                objectToWorld * objectMagnitude_[inst.mesh]);
        worldToObjectGain[inst.mesh] = std::max(worldToObjectGain[inst.mesh], worldToObject);
        conditioning[inst.mesh] = std::max(conditioning[inst.mesh], worldToObject * objectToWorld);
    }
    // Step: per mesh, the padding for boxes of its magnitude and for ray
    // origins mapped into its object space (docs/acceleration-structures.md).
    neededPadding_.assign(meshes.size(), 0.f);
    for (std::size_t id = 0; id < meshes.size(); ++id) {
        const double originInObject = 3.0 * worldToObjectGain[id] * originBound;
        neededPadding_[id] = quantizePaddingUp(static_cast<float>(
            conditioning[id] * conservativeBoxPadding(objectMagnitude_[id], static_cast<float>(originInObject))));
    }
}

float AccelManager::requiredPadding(ecs::MeshId mesh) const {
    return mesh < neededPadding_.size() ? neededPadding_[mesh] : 0.f;
}

EmbreeDevice::EmbreeDevice(int threads) {
    const std::string config = threads > 0 ? "threads=" + std::to_string(threads) : std::string();
    device_ = rtcNewDevice(config.c_str());
    if (!device_) throw std::runtime_error("cannot create Embree device");
    rtcSetDeviceErrorFunction(device_, embreeErrorHandler, nullptr);
    rtcSetDeviceMemoryMonitorFunction(
        device_,
        [](void* user, ssize_t bytes, bool) {
            static_cast<std::atomic<std::int64_t>*>(user)->fetch_add(bytes, std::memory_order_relaxed);
            return true;
        },
        &bytes_);
}

EmbreeDevice::~EmbreeDevice() { rtcReleaseDevice(device_); }

struct AccelManager::Blas {
    RTCScene scene = nullptr;
    std::vector<RTCGeometry> geometries;
    std::vector<GeometryInfo> info;
    std::vector<std::vector<Aabb>> boxes;                          // procedural AABBs (user data of the geometry)
    std::vector<std::unique_ptr<WatertightTriangles>> watertight;  // per geometry; null unless watertight triangles
    std::vector<std::vector<std::uint32_t>> clusterOrder;          // per deformable geometry: build-time order
    std::uint32_t refitsSinceCheck = 0;

    // Refit cost / rebuild cost at the current positions (>= ~1).
    double degradation(const ecs::MeshAsset& mesh) const {
        double refitCost = 0.0, rebuildCost = 0.0;
        for (std::size_t i = 0; i < clusterOrder.size() && i < mesh.geometries.size(); ++i)
            if (!clusterOrder[i].empty()) {
                refitCost += clusterCost(mesh.geometries[i], clusterOrder[i]);
                rebuildCost += clusterCost(mesh.geometries[i], mortonTriangleOrder(mesh.geometries[i]));
            }
        return rebuildCost > 0.0 ? refitCost / rebuildCost : 1.0;
    }
    ~Blas() {
        if (scene) rtcReleaseScene(scene);
    }
};

AccelManager::AccelManager(AccelOptions options) : options_(options), device_(options.threads) {}

std::uint64_t AccelManager::clusterBytes() const {
    std::uint64_t bytes = 0;
    for (const auto& blas : blases_)
        if (blas)
            for (const auto& w : blas->watertight)
                if (w) bytes += w->clusters.size() * sizeof(TriangleCluster);
    return bytes;
}

AccelManager::~AccelManager() {
    if (tlas_) rtcReleaseScene(tlas_);
}

RTCSceneFlags AccelManager::sceneFlags() const {
    // The context filter is how the pipeline runs any-hit logic and DXR culling.
    return static_cast<RTCSceneFlags>((options_.robust ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE) |
                                      RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION);
}

void AccelManager::attachUserGeometry(Blas& blas, std::size_t primitives, void* userData, RTCBuildQuality quality,
                                      RTCBoundsFunction bounds, RTCIntersectFunctionN intersect,
                                      RTCOccludedFunctionN occluded) {
    RTCGeometry geom = rtcNewGeometry(device_.get(), RTC_GEOMETRY_TYPE_USER);
    rtcSetGeometryBuildQuality(geom, quality);
    rtcSetGeometryUserPrimitiveCount(geom, static_cast<unsigned>(primitives));
    rtcSetGeometryUserData(geom, userData);
    rtcSetGeometryBoundsFunction(geom, bounds, nullptr);
    rtcSetGeometryIntersectFunction(geom, intersect);
    rtcSetGeometryOccludedFunction(geom, occluded);
    rtcCommitGeometry(geom);
    rtcAttachGeometry(blas.scene, geom);  // geomID = geometry index in the mesh
    blas.geometries.push_back(geom);
    rtcReleaseGeometry(geom);  // the scene holds the reference
}

void AccelManager::buildBlas(const ecs::MeshAsset& mesh, ecs::MeshId id, const std::vector<ecs::Material>& materials) {
    if (blases_.size() <= id) blases_.resize(id + 1);
    auto blas = std::make_unique<Blas>();
    blas->scene = rtcNewScene(device_.get());
    // Embree honours a geometry's RTC_BUILD_QUALITY_REFIT only when the scene's
    // build quality is LOW (a two-level structure over per-geometry BVHs) AND
    // the scene is RTC_SCENE_FLAG_DYNAMIC: a static scene makes its
    // acceleration structures immutable after each commit and re-creates them
    // on the next one, so every "refit" would be a full rebuild
    // (docs/acceleration-structures.md, "Refit in Embree").
    bool deformable = false;
    for (const ecs::Geometry& g : mesh.geometries) deformable = deformable || g.deformable();
    rtcSetSceneFlags(blas->scene, static_cast<RTCSceneFlags>(
                                      sceneFlags() | (deformable ? RTC_SCENE_FLAG_DYNAMIC : RTC_SCENE_FLAG_NONE)));
    if (deformable) rtcSetSceneBuildQuality(blas->scene, RTC_BUILD_QUALITY_LOW);
    blas->boxes.reserve(mesh.geometries.size());
    for (const ecs::Geometry& g : mesh.geometries) {
        GeometryInfo info;
        info.procedural = g.procedural();
        info.opaque = g.material >= materials.size() || materials[g.material].alphaMode == ecs::AlphaMode::Opaque;
        blas->info.push_back(info);
        blas->boxes.push_back(g.proceduralBoxes);
        // Per-geometry side tables stay index-aligned with the geometries.
        const bool refitTracked = !info.procedural && g.deformable() && options_.refitRebuildThreshold > 0.f;
        const bool watertightTriangles = !info.procedural && options_.watertight;
        std::vector<std::uint32_t> order =
            refitTracked || watertightTriangles ? mortonTriangleOrder(g) : std::vector<std::uint32_t>{};
        blas->watertight.emplace_back();
        if (info.procedural) {
            blas->clusterOrder.emplace_back();
            attachUserGeometry(*blas, g.proceduralBoxes.size(), blas->boxes.back().data(), RTC_BUILD_QUALITY_HIGH,
                               proceduralBoundsCallback, proceduralIntersectCallback, proceduralOccludedCallback);
            continue;
        }
        if (options_.watertight) {
            blas->watertight.back() = std::make_unique<WatertightTriangles>();
            WatertightTriangles& data = *blas->watertight.back();
            buildClusters(data, g, order);
            data.padding = requiredPadding(id);
            if (refitTracked) blas->clusterOrder.push_back(std::move(order));
            else blas->clusterOrder.emplace_back();
            attachUserGeometry(*blas, data.clusters.size(), &data,
                               g.deformable() ? RTC_BUILD_QUALITY_REFIT : RTC_BUILD_QUALITY_HIGH,
                               watertightBoundsCallback, watertightIntersectCallback, watertightOccludedCallback);
            continue;
        }
        blas->clusterOrder.push_back(refitTracked ? std::move(order) : std::vector<std::uint32_t>{});
        RTCGeometry geom = rtcNewGeometry(device_.get(), RTC_GEOMETRY_TYPE_TRIANGLE);
        // Deformable geometry keeps a refittable BVH.
        rtcSetGeometryBuildQuality(geom, g.deformable() ? RTC_BUILD_QUALITY_REFIT : RTC_BUILD_QUALITY_HIGH);
        uploadVertices(geom, g, true);
        auto* idx = static_cast<std::uint32_t*>(rtcSetNewGeometryBuffer(
            geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, sizeof(std::uint32_t) * 3, g.triangleCount()));
        std::memcpy(idx, g.indices.data(), g.triangleCount() * 3 * sizeof(std::uint32_t));
        rtcCommitGeometry(geom);
        rtcAttachGeometry(blas->scene, geom);  // geomID = geometry index in the mesh
        blas->geometries.push_back(geom);
        rtcReleaseGeometry(geom);  // the scene holds the reference
    }
    rtcCommitScene(blas->scene);
    blases_[id] = std::move(blas);
}

void AccelManager::refitBlas(const ecs::MeshAsset& mesh, ecs::MeshId id) {
    Blas& blas = *blases_.at(id);
    for (std::size_t i = 0; i < mesh.geometries.size(); ++i) {
        if (blas.info[i].procedural) continue;
        if (blas.watertight[i]) {
            refreshClusterVertices(*blas.watertight[i], mesh.geometries[i]);
            blas.watertight[i]->padding = requiredPadding(id);
            rtcCommitGeometry(blas.geometries[i]);
            continue;
        }
        uploadVertices(blas.geometries[i], mesh.geometries[i], false);
        rtcCommitGeometry(blas.geometries[i]);
    }
    rtcCommitScene(blas.scene);
}

void AccelManager::rebuildTlas(const ecs::SceneSnapshot& scene) {
    if (tlas_) rtcReleaseScene(tlas_);
    tlas_ = rtcNewScene(device_.get());
    rtcSetSceneFlags(tlas_, sceneFlags());
    instances_ = scene.instances;
    instIdByEntityIndex_.clear();
    for (std::uint32_t i = 0; i < instances_.size(); ++i) {
        const ecs::InstanceSnapshot& inst = instances_[i];
        RTCGeometry geom = rtcNewGeometry(device_.get(), RTC_GEOMETRY_TYPE_INSTANCE);
        rtcSetGeometryInstancedScene(geom, blases_.at(inst.mesh)->scene);
        rtcSetGeometryTransform(geom, 0, RTC_FORMAT_FLOAT4X4_COLUMN_MAJOR, &inst.worldFromObject[0][0]);
        rtcSetGeometryMask(geom, inst.mask);
        rtcCommitGeometry(geom);
        rtcAttachGeometryByID(tlas_, geom, i);
        rtcReleaseGeometry(geom);
        if (instIdByEntityIndex_.size() <= inst.entity.index) instIdByEntityIndex_.resize(inst.entity.index + 1, ~0u);
        instIdByEntityIndex_[inst.entity.index] = i;
    }
    rtcCommitScene(tlas_);
}

const GeometryInfo& AccelManager::geometryInfo(ecs::MeshId mesh, std::uint32_t geometryIndex) const {
    return blases_.at(mesh)->info.at(geometryIndex);
}

std::uint32_t AccelManager::geometryCount(ecs::MeshId mesh) const {
    return mesh < blases_.size() && blases_[mesh] ? static_cast<std::uint32_t>(blases_[mesh]->info.size()) : 0;
}

AccelUpdateStats AccelManager::update(const ecs::SceneSnapshot& scene) {
    AccelUpdateStats stats;
    const Stopwatch clock;
    const ecs::FrameUpdate& u = scene.update;
    const auto& meshes = *scene.meshes;

    // Step: the conservative padding every mesh needs for this frame's
    // instances, camera and changed geometry.
    std::vector<std::uint8_t> touched(meshes.size(), 0);
    for (ecs::MeshId id : u.rebuiltMeshes) touched.at(id) = 1;
    for (ecs::MeshId id : u.refitMeshes) touched.at(id) = 1;
    updateConservativePadding(scene, touched);
    std::fill(touched.begin(), touched.end(), 0);

    // Step: BLAS work, exactly what the FrameUpdate lists.
    const std::vector<ecs::Material>& materials = *scene.materials;
    bool rebuiltForQuality = false;
    for (ecs::MeshId id : u.rebuiltMeshes) {
        buildBlas(meshes.at(id), id, materials);
        touched[id] = 1;
        ++stats.blasRebuilt;
    }
    for (ecs::MeshId id : u.refitMeshes) {
        if (id >= blases_.size() || !blases_[id]) {  // never built: build instead
            buildBlas(meshes.at(id), id, materials);
            ++stats.blasRebuilt;
        } else {
            // Quality policy: every refitQualityCheckInterval refits, rebuild
            // instead when a rebuild would make a much tighter hierarchy.
            Blas& blas = *blases_[id];
            double degradation = 1.0;
            if (options_.refitRebuildThreshold > 0.f &&
                ++blas.refitsSinceCheck >= std::max<std::uint32_t>(1, options_.refitQualityCheckInterval)) {
                blas.refitsSinceCheck = 0;
                degradation = blas.degradation(meshes.at(id));
                stats.worstRefitDegradation = std::max(stats.worstRefitDegradation, static_cast<float>(degradation));
            }
            if (options_.refitRebuildThreshold > 0.f && degradation > options_.refitRebuildThreshold) {
                buildBlas(meshes.at(id), id, materials);
                ++stats.blasRebuilt;
                ++stats.blasRebuiltForQuality;
                rebuiltForQuality = true;
            } else {
                refitBlas(meshes.at(id), id);
                ++stats.blasRefit;
            }
        }
        touched[id] = 1;
    }
    // Step: untouched BLASes whose cluster boxes are now padded too little
    // (ray origins grew in magnitude, an instance scaled down): pad again.
    bool repadded = false;
    for (std::size_t id = 0; id < meshes.size() && id < blases_.size(); ++id) {
        if (touched[id] || !blases_[id]) continue;
        Blas& blas = *blases_[id];
        bool grew = false;
        for (std::size_t i = 0; i < blas.watertight.size(); ++i)
            if (blas.watertight[i] && blas.watertight[i]->padding < requiredPadding(static_cast<ecs::MeshId>(id))) {
                blas.watertight[i]->padding = requiredPadding(static_cast<ecs::MeshId>(id));
                rtcCommitGeometry(blas.geometries[i]);
                grew = true;
            }
        if (!grew) {
            ++stats.blasReused;
            continue;
        }
        rtcCommitScene(blas.scene);
        touched[id] = 1;
        repadded = true;
        ++stats.blasRepadded;
    }

    // Step: opacity follows material edits (alpha mode) without a rebuild.
    if (u.materialsChanged)
        for (std::size_t id = 0; id < blases_.size() && id < meshes.size(); ++id)
            if (blases_[id])
                for (std::size_t g = 0; g < blases_[id]->info.size(); ++g) {
                    const ecs::MaterialId m = meshes[id].geometries[g].material;
                    blases_[id]->info[g].opaque =
                        m >= materials.size() || materials[m].alphaMode == ecs::AlphaMode::Opaque;
                }

    // Step: shader-table slots, one per geometry, meshes in id order.
    slotBase_.resize(meshes.size());
    slotCount_ = 0;
    for (std::size_t id = 0; id < meshes.size(); ++id) {
        slotBase_[id] = slotCount_;
        slotCount_ += static_cast<std::uint32_t>(meshes[id].geometries.size());
    }

    // Step: TLAS. A rebuilt BLAS is a new RTCScene, so instances of it need re-pointing: rebuild.
    // The snapshot's instances may differ from the TLAS's without an
    // instance-set change: an instance whose transform turned untraceable
    // (scaled to 0) leaves the snapshot, and comes back.
    const bool sameInstances =
        scene.instances.size() == instances_.size() &&
        std::equal(scene.instances.begin(), scene.instances.end(), instances_.begin(),
                   [](const ecs::InstanceSnapshot& a, const ecs::InstanceSnapshot& b) { return a.entity == b.entity; });
    if (!tlas_ || u.instanceSetChanged || !u.rebuiltMeshes.empty() || rebuiltForQuality || !sameInstances) {
        rebuildTlas(scene);
        ++stats.tlasBuilds;
    } else if (!u.movedInstances.empty() || !u.refitMeshes.empty() || repadded) {
        for (const ecs::Entity e : u.movedInstances) {
            if (e.index >= instIdByEntityIndex_.size() || instIdByEntityIndex_[e.index] == ~0u) continue;
            const std::uint32_t id = instIdByEntityIndex_[e.index];
            // Snapshot instances are sorted by entity index.
            const auto it = std::lower_bound(
                scene.instances.begin(), scene.instances.end(), e.index,
                [](const ecs::InstanceSnapshot& inst, std::uint32_t index) { return inst.entity.index < index; });
            if (it == scene.instances.end() || it->entity != e) continue;
            instances_[id] = *it;
            RTCGeometry geom = rtcGetGeometry(tlas_, id);
            rtcSetGeometryTransform(geom, 0, RTC_FORMAT_FLOAT4X4_COLUMN_MAJOR, &instances_[id].worldFromObject[0][0]);
            rtcCommitGeometry(geom);
            ++stats.instancesMoved;
        }
        // Instances of refit or re-padded meshes: their bounds changed with the BLAS.
        if (!u.refitMeshes.empty() || repadded)
            for (std::uint32_t id = 0; id < instances_.size(); ++id)
                if (touched[instances_[id].mesh]) rtcCommitGeometry(rtcGetGeometry(tlas_, id));
        rtcCommitScene(tlas_);
        ++stats.tlasUpdates;
    }
    refreshInstanceFacts();
    stats.buildMs = clock.elapsedMs();
    return stats;
}

void AccelManager::refreshInstanceFacts() {
    instanceFacts_.resize(instances_.size());
    allOpaque_ = true;
    anyProcedural_ = false;
    for (std::size_t i = 0; i < instances_.size(); ++i) {
        const ecs::InstanceSnapshot& inst = instances_[i];
        InstanceFacts& f = instanceFacts_[i];
        f = InstanceFacts{};
        f.normalFromObject = glm::transpose(glm::inverse(mat3(inst.worldFromObject)));
        f.objectFromWorld = objectFromWorldOf(inst.worldFromObject);
        f.frontCounterClockwise = (inst.flags & InstanceFlag::TriangleFrontCounterClockwise) != 0;
        f.geometrySlotBase = slotBase_.at(inst.mesh);
        f.hitGroupOffset = inst.hitGroupOffset;
        for (const GeometryInfo& g : blases_.at(inst.mesh)->info) {
            f.hasProcedural = f.hasProcedural || g.procedural;
            f.mayBeNonOpaque = f.mayBeNonOpaque || !g.opaque;
        }
        if (inst.flags & InstanceFlag::ForceOpaque) f.mayBeNonOpaque = false;
        if (inst.flags & InstanceFlag::ForceNonOpaque) f.mayBeNonOpaque = true;
        allOpaque_ = allOpaque_ && !f.mayBeNonOpaque;
        anyProcedural_ = anyProcedural_ || f.hasProcedural;
    }
}

}  // namespace rtlab::tracer
