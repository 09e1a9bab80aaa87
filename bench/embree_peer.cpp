#include "embree_peer.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <vector>

#include "core/timer.h"

namespace kestrel::peer {

const char* embree_quality_name(EmbreeQuality q) {
  switch (q) {
    case EmbreeQuality::low:
      return "LOW";
    case EmbreeQuality::medium:
      return "MEDIUM";
    case EmbreeQuality::high:
      return "HIGH";
    case EmbreeQuality::refit:
      return "REFIT";
  }
  return "?";
}

namespace {
bool memory_monitor(void* user, ssize_t bytes, bool) {
  static_cast<std::atomic<ssize_t>*>(user)->fetch_add(bytes);
  return true;
}
}  // namespace

struct EmbreeScene::Impl {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  RTCBuildQuality quality;
  std::vector<float> vertices;    // x y z, padded by one float at the end (Embree reads 16 B)
  std::vector<uint32_t> indices;  // 3 per triangle, global prim order
  double build_ms = 0;
  std::atomic<ssize_t> memory{0};
  ssize_t memory_before_build = 0;

  void release_scene() {
    if (scene) rtcReleaseScene(scene);
    scene = nullptr;
  }

  double build() {
    release_scene();
    memory_before_build = memory.load();
    scene = rtcNewScene(device);
    // REFIT is a geometry quality: Embree refits a geometry's BVH only under its two-level
    // builder, which a dynamic LOW-quality scene selects.
    const bool refit = quality == RTC_BUILD_QUALITY_REFIT;
    rtcSetSceneBuildQuality(scene, refit ? RTC_BUILD_QUALITY_LOW : quality);
    rtcSetSceneFlags(scene, refit ? RTC_SCENE_FLAG_DYNAMIC : RTC_SCENE_FLAG_NONE);
    RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetGeometryBuildQuality(geom, quality);
    rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, vertices.data(),
                               0, 3 * sizeof(float), (vertices.size() - 1) / 3);
    rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, indices.data(), 0,
                               3 * sizeof(uint32_t), indices.size() / 3);
    rtcCommitGeometry(geom);
    rtcAttachGeometryByID(scene, geom, 0);
    rtcReleaseGeometry(geom);
    Timer t;
    rtcCommitScene(scene);
    build_ms = t.ms();
    return build_ms;
  }
};

EmbreeScene::EmbreeScene(const Scene& scene, EmbreeQuality quality, int threads) : impl_(new Impl) {
  Impl& m = *impl_;
  const std::string config =
      threads > 0 ? "threads=" + std::to_string(threads) + ",set_affinity=0" : "";
  m.device = rtcNewDevice(config.empty() ? nullptr : config.c_str());
  if (!m.device) throw std::runtime_error("Embree: rtcNewDevice failed");
  rtcSetDeviceMemoryMonitorFunction(m.device, memory_monitor, &m.memory);
  m.quality = quality == EmbreeQuality::low      ? RTC_BUILD_QUALITY_LOW
              : quality == EmbreeQuality::medium ? RTC_BUILD_QUALITY_MEDIUM
              : quality == EmbreeQuality::refit  ? RTC_BUILD_QUALITY_REFIT
                                                 : RTC_BUILD_QUALITY_HIGH;
  const SceneValidation validation = validate_scene(scene);
  size_t gid = 0;
  for (const TriangleMesh& mesh : scene.meshes) {
    const uint32_t base = uint32_t(m.vertices.size() / 3);
    for (const Vec3& p : mesh.positions) {
      m.vertices.push_back(std::isfinite(p.x) ? p.x : 0.0f);
      m.vertices.push_back(std::isfinite(p.y) ? p.y : 0.0f);
      m.vertices.push_back(std::isfinite(p.z) ? p.z : 0.0f);
    }
    for (size_t t = 0; t < mesh.triangle_count(); ++t, ++gid)
      for (int k = 0; k < 3; ++k)
        m.indices.push_back(validation.valid[gid] ? base + mesh.indices[3 * t + k] : 0u);
  }
  m.vertices.push_back(0.0f);
  if (m.vertices.size() < 4) m.vertices.assign(4, 0.0f);
  m.build();
}

EmbreeScene::~EmbreeScene() {
  impl_->release_scene();
  if (impl_->device) rtcReleaseDevice(impl_->device);
}

double EmbreeScene::rebuild() {
  return impl_->build();
}
double EmbreeScene::update_vertices(std::span<const Vec3> positions) {
  Impl& m = *impl_;
  if (positions.size() != (m.vertices.size() - 1) / 3)
    throw std::runtime_error("Embree peer: update_vertices got a different vertex count");
  for (size_t i = 0; i < positions.size(); ++i) {
    m.vertices[3 * i + 0] = std::isfinite(positions[i].x) ? positions[i].x : 0.0f;
    m.vertices[3 * i + 1] = std::isfinite(positions[i].y) ? positions[i].y : 0.0f;
    m.vertices[3 * i + 2] = std::isfinite(positions[i].z) ? positions[i].z : 0.0f;
  }
  RTCGeometry geom = rtcGetGeometry(m.scene, 0);
  rtcUpdateGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0);
  rtcCommitGeometry(geom);
  Timer t;
  rtcCommitScene(m.scene);
  m.build_ms = t.ms();
  return m.build_ms;
}

double EmbreeScene::last_build_ms() const {
  return impl_->build_ms;
}
size_t EmbreeScene::memory_bytes() const {
  return size_t(impl_->memory.load() - impl_->memory_before_build);
}

Hit EmbreeScene::intersect(const Ray& ray) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRayHit rh;
  rh.ray = {ray.org.x, ray.org.y, ray.org.z, ray.tmin,    ray.dir.x, ray.dir.y,
            ray.dir.z, 0.0f,      ray.tmax,  0xFFFFFFFFu, 0,         0};
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(impl_->scene, &ctx, &rh);
  Hit hit;
  if (rh.hit.geomID != RTC_INVALID_GEOMETRY_ID) {
    hit.t = rh.ray.tfar;
    hit.prim_id = rh.hit.primID;
    hit.u = rh.hit.u;
    hit.v = rh.hit.v;
  }
  return hit;
}

bool EmbreeScene::occluded(const Ray& ray) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRay r{ray.org.x, ray.org.y, ray.org.z, ray.tmin,    ray.dir.x, ray.dir.y,
           ray.dir.z, 0.0f,      ray.tmax,  0xFFFFFFFFu, 0,         0};
  rtcOccluded1(impl_->scene, &ctx, &r);
  return r.tfar == -std::numeric_limits<float>::infinity();
}

void EmbreeScene::intersect(std::span<const Ray> rays, std::span<Hit> hits) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  for (size_t i = 0; i < rays.size(); ++i) {
    const Ray& ray = rays[i];
    RTCRayHit rh;
    rh.ray = {ray.org.x, ray.org.y, ray.org.z, ray.tmin,    ray.dir.x, ray.dir.y,
              ray.dir.z, 0.0f,      ray.tmax,  0xFFFFFFFFu, 0,         0};
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(impl_->scene, &ctx, &rh);
    Hit& hit = hits[i];
    if (rh.hit.geomID != RTC_INVALID_GEOMETRY_ID) {
      hit = {rh.ray.tfar, rh.hit.primID, rh.hit.u, rh.hit.v};
    } else {
      hit = Hit{};
    }
  }
}

void EmbreeScene::occluded(std::span<const Ray> rays, std::span<uint8_t> out) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  for (size_t i = 0; i < rays.size(); ++i) {
    const Ray& ray = rays[i];
    RTCRay r{ray.org.x, ray.org.y, ray.org.z, ray.tmin,    ray.dir.x, ray.dir.y,
             ray.dir.z, 0.0f,      ray.tmax,  0xFFFFFFFFu, 0,         0};
    rtcOccluded1(impl_->scene, &ctx, &r);
    out[i] = r.tfar == -std::numeric_limits<float>::infinity();
  }
}

void EmbreeScene::intersect16(std::span<const Ray> rays, std::span<Hit> hits) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  alignas(64) RTCRayHit16 rh;
  alignas(64) int valid[16];
  for (size_t base = 0; base < rays.size(); base += 16) {
    const size_t n = std::min<size_t>(16, rays.size() - base);
    for (size_t k = 0; k < 16; ++k) {
      const Ray& r = rays[base + std::min(k, n - 1)];
      valid[k] = k < n ? -1 : 0;
      rh.ray.org_x[k] = r.org.x, rh.ray.org_y[k] = r.org.y, rh.ray.org_z[k] = r.org.z;
      rh.ray.dir_x[k] = r.dir.x, rh.ray.dir_y[k] = r.dir.y, rh.ray.dir_z[k] = r.dir.z;
      rh.ray.tnear[k] = r.tmin, rh.ray.tfar[k] = r.tmax, rh.ray.time[k] = 0;
      rh.ray.mask[k] = 0xFFFFFFFFu, rh.ray.id[k] = 0, rh.ray.flags[k] = 0;
      rh.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;
      rh.hit.primID[k] = RTC_INVALID_GEOMETRY_ID;
    }
    rtcIntersect16(valid, impl_->scene, &ctx, &rh);
    for (size_t k = 0; k < n; ++k) {
      Hit& hit = hits[base + k];
      if (rh.hit.geomID[k] != RTC_INVALID_GEOMETRY_ID)
        hit = {rh.ray.tfar[k], rh.hit.primID[k], rh.hit.u[k], rh.hit.v[k]};
      else
        hit = Hit{};
    }
  }
}

std::string embree_version() {
  return RTC_VERSION_STRING;
}

}  // namespace kestrel::peer
