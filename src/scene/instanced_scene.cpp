// Two-level scenes: a BLAS per mesh (refit or rebuilt when its vertices move), a TLAS over
// the instances rebuilt at every commit(), and traversal through both in the SIMD kernels.
#include <fmt/format.h>

#include <cmath>

#include "core/parallel.h"
#include "core/timer.h"
#include "core/vec.h"
#include "geometry/triangle_intersect.h"
#include "kestrel/error.h"
#include "kestrel/instances.h"
#include "scene/instance_tree.h"
#include "scene/transforms.h"
#include "traverse/kernels.h"
#include "traverse/stream.h"
#include "traverse/wide_bvh.h"

namespace kestrel {

// ---- the scene ------------------------------------------------------------------------------

Layout resolve_layout(Layout layout);  // accel.cpp

struct InstancedScene::Impl {
  struct MeshSlot {
    bool live = false, built = false, dirty = false;
    Scene scene;  // one mesh: what build_accel / refit_accel take
    Accel blas;
    double sah_built = 0;  // SAH cost right after the last full build
  };
  struct InstanceSlot {
    bool live = false;
    MeshId mesh = 0;
    Affine3 transform, inverse;
    uint32_t mask = 0xFFFFFFFFu;
  };
  SceneConfig config;
  Layout layout = Layout::bvh8;
  std::vector<Material> materials;
  std::vector<Texture> textures;
  std::vector<Light> lights;
  std::string source;
  uint64_t generation = 0;
  // As of the last commit(): the BLAS of the only instance when it is the identity with every
  // mask bit set (traced as a single-level Accel), else null.
  uint32_t direct_mesh = invalid_id, direct_id = invalid_id;
  const Accel* direct() const {
    return direct_mesh < meshes.size() && meshes[direct_mesh].built ? &meshes[direct_mesh].blas
                                                                    : nullptr;
  }
  std::vector<MeshSlot> meshes;
  std::vector<InstanceSlot> instances;
  // As of the last commit().
  Buffer<Bvh4Node> tlas4;
  Buffer<Bvh8Node> tlas8;
  // Coherent batches as packets or single rays, timed as they run (closest hit, any hit):
  // what is measured holds until the meshes change.
  mutable PacketChoice closest_choice, any_choice;
  std::vector<kernels::InstanceData> data;
  Buffer<PrimRef> refs;  // kept between commits: no fresh pages every frame
  Bounds3 world;         // of the instances' world boxes, as of the last commit()
  InstanceTreeScratch tree_scratch;

  MeshSlot& mesh(MeshId id, const char* what) {
    if (id >= meshes.size() || !meshes[id].live)
      throw Error(ErrorCode::invalid_argument, fmt::format("{}: no mesh {}", what, id));
    return meshes[id];
  }
  InstanceSlot& instance(InstanceId id, const char* what) {
    if (id >= instances.size() || !instances[id].live)
      throw Error(ErrorCode::invalid_argument, fmt::format("{}: no instance {}", what, id));
    return instances[id];
  }
  static void check_transform(InstanceId id, const Affine3& t) {
    if (const std::string p = transform_problem(t); !p.empty())
      throw Error(ErrorCode::invalid_argument, fmt::format("instance {}: {}", id, p));
  }
  void build_blas(MeshSlot& m) {
    BuildConfig c = config.blas;
    c.layout = layout;
    m.blas = build_accel(m.scene, c);
    m.sah_built = layout == Layout::bvh4 ? wide_sah_cost(m.blas.nodes->bvh4)
                                         : wide_sah_cost(m.blas.nodes->bvh8);
    m.built = true;
    m.dirty = false;
  }
  bool empty_tlas() const { return layout == Layout::bvh4 ? tlas4.empty() : tlas8.empty(); }
  const void* tlas_data() const {
    return layout == Layout::bvh4 ? static_cast<const void*>(tlas4.data())
                                  : static_cast<const void*>(tlas8.data());
  }
};

InstancedScene::InstancedScene(SceneConfig config) : impl_(new Impl) {
  check_build_config(config.blas);
  check_build_config(config.tlas);
  if (!(config.refit_sah_factor >= 1.0f))
    throw Error(
        ErrorCode::invalid_argument,
        fmt::format("SceneConfig: refit_sah_factor = {} must be >= 1", config.refit_sah_factor));
  config.tlas.max_leaf_size = 1;
  impl_->config = config;
  // The TLAS and every BLAS share one width, the kernels' (bvh2 is a reference layout for
  // single-level accels only).
  const Layout l = resolve_layout(config.blas.layout);
  impl_->layout = l == Layout::bvh4 ? Layout::bvh4 : Layout::bvh8;
}

InstancedScene::~InstancedScene() = default;
InstancedScene::InstancedScene(InstancedScene&&) noexcept = default;
InstancedScene& InstancedScene::operator=(InstancedScene&&) noexcept = default;

MeshId InstancedScene::add_mesh(TriangleMesh mesh) {
  Impl::MeshSlot slot;
  slot.live = true;
  slot.dirty = true;
  slot.scene.meshes.push_back(std::move(mesh));
  impl_->meshes.push_back(std::move(slot));
  return MeshId(impl_->meshes.size() - 1);
}

InstanceId InstancedScene::add_instance(MeshId mesh, const Affine3& transform, uint32_t mask) {
  impl_->mesh(mesh, "add_instance");
  const InstanceId id = InstanceId(impl_->instances.size());
  Impl::check_transform(id, transform);
  Impl::InstanceSlot slot;
  slot.live = true;
  slot.mesh = mesh;
  slot.transform = transform;
  slot.inverse = inverse_of_valid(transform);  // checked just above
  slot.mask = mask;
  impl_->instances.push_back(slot);
  return id;
}

void InstancedScene::set_transform(InstanceId id, const Affine3& transform) {
  Impl::InstanceSlot& slot = impl_->instance(id, "set_transform");
  Impl::check_transform(id, transform);
  slot.transform = transform;
  slot.inverse = inverse_of_valid(transform);
}

void InstancedScene::set_mask(InstanceId id, uint32_t mask) {
  impl_->instance(id, "set_mask").mask = mask;
}

void InstancedScene::update_vertices(MeshId id, std::span<const Vec3> positions,
                                     std::span<const Vec3> normals) {
  Impl::MeshSlot& m = impl_->mesh(id, "update_vertices");
  std::vector<Vec3>& p = m.scene.meshes[0].positions;
  if (positions.size() != p.size())
    throw Error(ErrorCode::invalid_argument,
                fmt::format("update_vertices: mesh {} has {} vertices, got {}", id, p.size(),
                            positions.size()));
  std::copy(positions.begin(), positions.end(), p.begin());
  std::vector<Vec3>& n = m.scene.meshes[0].normals;
  if (!normals.empty() && normals.size() == n.size())
    std::copy(normals.begin(), normals.end(), n.begin());
  m.dirty = true;
}

void InstancedScene::remove_instance(InstanceId id) {
  impl_->instance(id, "remove_instance").live = false;
}

void InstancedScene::remove_mesh(MeshId id) {
  Impl::MeshSlot& m = impl_->mesh(id, "remove_mesh");
  for (size_t i = 0; i < impl_->instances.size(); ++i)
    if (impl_->instances[i].live && impl_->instances[i].mesh == id)
      throw Error(ErrorCode::invalid_argument,
                  fmt::format("remove_mesh: mesh {} is used by instance {}", id, i));
  m = Impl::MeshSlot{};
}

CommitStats InstancedScene::commit() {
  Impl& s = *impl_;
  CommitStats stats;
  Timer total;
  for (Impl::MeshSlot& m : s.meshes) {
    if (!m.live || (m.built && !m.dirty)) continue;
    Timer t;
    if (!m.built) {
      s.build_blas(m);
      stats.blas_build_ms += t.ms();
      ++stats.blas_builds;
      continue;
    }
    bool rebuild = false;
    try {
      const double sah = refit_accel_cost(m.blas, m.scene);
      rebuild = sah > double(s.config.refit_sah_factor) * m.sah_built;
    } catch (const Error&) {
      rebuild = true;  // a triangle became invalid (or valid): the tree must be rebuilt
    }
    if (rebuild) {
      s.build_blas(m);
      stats.blas_build_ms += t.ms();
      ++stats.blas_builds;
    } else {
      m.dirty = false;
      stats.blas_refit_ms += t.ms();
      ++stats.blas_refits;
    }
  }
  // TLAS over the instances whose mesh has triangles.
  Timer tt;
  s.data.clear();
  s.world = Bounds3{};
  Buffer<PrimRef>& refs = s.refs;
  refs.clear();
  refs.reserve(s.instances.size());
  s.data.reserve(s.instances.size());
  Bounds3 centres;  // of lo + hi, for the instance tree's Morton codes
  for (size_t i = 0; i < s.instances.size(); ++i) {
    const Impl::InstanceSlot& inst = s.instances[i];
    if (!inst.live) continue;
    const Impl::MeshSlot& m = s.meshes[inst.mesh];
    if (m.blas.prim_count == 0) continue;
    // World box of the transformed object box (Arvo 1990): centre through the transform,
    // half extent through |M|; widened by a few ulps so rounding never makes it too small.
    const Bounds3& b = m.blas.bounds;
    const float* M = inst.transform.m;
    const float c[3] = {0.5f * (b.lo.x + b.hi.x), 0.5f * (b.lo.y + b.hi.y),
                        0.5f * (b.lo.z + b.hi.z)};
    const float e[3] = {0.5f * (b.hi.x - b.lo.x), 0.5f * (b.hi.y - b.lo.y),
                        0.5f * (b.hi.z - b.lo.z)};
    float lo[3], hi[3];
    for (int r = 0; r < 3; ++r) {
      const float* row = M + 4 * r;
      const float wc = row[0] * c[0] + row[1] * c[1] + row[2] * c[2] + row[3];
      const float we =
          std::fabs(row[0]) * e[0] + std::fabs(row[1]) * e[1] + std::fabs(row[2]) * e[2];
      const float pad = 1e-6f * (std::fabs(wc) + we);
      lo[r] = wc - we - pad;
      hi[r] = wc + we + pad;
    }
    PrimRef r;
    r.lo = {lo[0], lo[1], lo[2]};
    r.hi = {hi[0], hi[1], hi[2]};
    s.world = {min(s.world.lo, r.lo), max(s.world.hi, r.hi)};
    const Vec3 c2{lo[0] + hi[0], lo[1] + hi[1], lo[2] + hi[2]};
    centres = {min(centres.lo, c2), max(centres.hi, c2)};
    r.prim_id = uint32_t(s.data.size());
    refs.push_back(r);
    kernels::InstanceData d;
    std::copy(inst.inverse.m, inst.inverse.m + 12, d.world_to_object);
    d.mask = inst.mask;
    d.id = uint32_t(i);
    if (s.layout == Layout::bvh4) {
      d.nodes = m.blas.nodes->bvh4.nodes.data();
      d.blocks = m.blas.nodes->bvh4.blocks.data();
    } else {
      d.nodes = m.blas.nodes->bvh8.nodes.data();
      d.blocks = m.blas.nodes->bvh8.blocks.data();
    }
    s.data.push_back(d);
  }
  if (resolve_builder(s.config.tlas, refs.size()) == Builder::lbvh) {
    // The default: Morton order straight into wide nodes (instance_tree.h).
    if (s.layout == Layout::bvh4)
      build_instance_tree(refs, centres, s.tlas4, s.tree_scratch);
    else
      build_instance_tree(refs, centres, s.tlas8, s.tree_scratch);
  } else {
    // Any other builder: its binary tree, collapsed.
    const Bvh2 tlas = build_bvh(refs, s.config.tlas);
    if (s.layout == Layout::bvh4)
      s.tlas4 = collapse_instances_bvh4(tlas);
    else
      s.tlas8 = collapse_instances_bvh8(tlas);
  }
  stats.tlas_ms = tt.ms();
  stats.instances = s.data.size();
  s.direct_mesh = invalid_id, s.direct_id = invalid_id;
  if (s.data.size() == 1) {
    const Impl::InstanceSlot& inst = s.instances[s.data[0].id];
    const Affine3 identity;
    if (std::equal(std::begin(inst.transform.m), std::end(inst.transform.m),
                   std::begin(identity.m)) &&
        inst.mask == 0xFFFFFFFFu) {
      s.direct_mesh = inst.mesh;
      s.direct_id = s.data[0].id;
    }
  }
  ++s.generation;
  if (stats.blas_builds > 0) s.closest_choice.reset(), s.any_choice.reset();
  stats.total_ms = total.ms();
  return stats;
}

namespace {
// The kernel and tree a query runs on, or fn == nullptr when nothing can be hit.
struct TlasQuery {
  kernels::TlasFn fn = nullptr;
  kernels::TlasFn packet_fn = nullptr;  // coherent rays as lane packets (Bvh8 layout), or null
  const void* tlas = nullptr;
  // Traces a run of rays (traced(kernel)) as packets where asked or, unsaid, where the run
  // looks coherent (or is a stream's sorted chunk) and `choice` finds packets faster so far
  // (timing some runs each way).
  template <class Fn>
  void run(std::span<const Ray> rays, const TraceOptions& options, PacketChoice& choice,
           bool sorted, Fn&& traced) const {
    if (!packet_fn) return traced(fn);
    choice.run(
        options.packets, [&] { return sorted || looks_coherent(rays); }, rays.size(),
        [&](bool packets) { traced(packets ? packet_fn : fn); });
  }
};

// Checks a query's sizes and ISA and picks its two-level kernel.
TlasQuery prepare_query(const char* what, size_t rays, size_t results, const TraceOptions& options,
                        bool any_hit, Layout layout, const void* tlas, bool empty) {
  if (rays != results)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("{}: {} rays but room for {} results", what, rays, results));
  const Isa isa = options.isa.value_or(default_isa());
  if (!isa_supported(isa))
    throw Error(ErrorCode::invalid_argument,
                fmt::format("ISA '{}' is not supported by this CPU", isa_name(isa)));
  if (empty) return {};
  const kernels::Table& k = kernels::table_for(isa);
  const bool four = layout == Layout::bvh4;
  return {any_hit ? (four ? k.tlas_any4 : k.tlas_any8) : (four ? k.tlas_closest4 : k.tlas_closest8),
          four      ? nullptr
          : any_hit ? k.tlas_any_packet8
                    : k.tlas_packet8,
          tlas};
}
}  // namespace

void InstancedScene::trace(std::span<const Ray> rays, std::span<InstanceHit> hits,
                           uint32_t ray_mask, const TraceOptions& options) const {
  const Impl& s = *impl_;
  const TlasQuery q = prepare_query("trace", rays.size(), hits.size(), options, false, s.layout,
                                    s.tlas_data(), s.data.empty() || s.empty_tlas());
  if (!q.fn) {
    for (InstanceHit& h : hits) h = InstanceHit{};
    return;
  }
  if (const Accel* direct = s.direct();
      direct && ray_mask != 0) {  // one identity instance: its BLAS alone
    thread_local std::vector<Hit> scratch;
    scratch.resize(rays.size());
    kestrel::trace(*direct, rays, std::span<Hit>(scratch.data(), rays.size()), options);
    const Hit* found = scratch.data();  // scratch is this thread's: the workers see its pointer
    parallel_for(0, rays.size(), 16384, [&](size_t b, size_t e) {
      for (size_t i = b; i < e; ++i) {
        const Hit& h = found[i];
        hits[i] = h.hit() ? InstanceHit{h.t, h.prim_id, s.direct_id, h.u, h.v} : InstanceHit{};
      }
    });
    return;
  }
  // The kernels give untraceable rays a miss themselves (traverse/kernels.h).
  const auto run = [&](std::span<const Ray> r, InstanceHit* h, kernels::TlasFn fn) {
    fn(q.tlas, s.data.data(), r.data(), h, r.size(), ray_mask);
  };
  const size_t bytes = rays.size() >= stream_min_rays ? memory_bytes() : 0;  // walks the meshes
  if (stream_by_default(rays, s.world, bytes, false, false, options)) {      // traverse/stream.h
    PacketChoice choice;  // for this batch's sorted chunks, as the flat stream (trace.cpp)
    for_each_stream_chunk(rays, s.world, [&](const Ray* r, const uint32_t* callers, size_t n) {
      InstanceHit local[stream_chunk];
      const std::span<const Ray> chunk(r, n);
      q.run(chunk, options, choice, true, [&](kernels::TlasFn fn) { run(chunk, local, fn); });
      for (size_t j = 0; j < n; ++j) hits[callers[j]] = local[j];
    });
    return;
  }
  parallel_for(0, rays.size(), 1024, [&](size_t b, size_t e) {
    const auto chunk = rays.subspan(b, e - b);
    q.run(chunk, options, s.closest_choice, false,
          [&](kernels::TlasFn fn) { run(chunk, hits.data() + b, fn); });
  });
}

void InstancedScene::occluded(std::span<const Ray> rays, std::span<uint8_t> out, uint32_t ray_mask,
                              const TraceOptions& options) const {
  const Impl& s = *impl_;
  const TlasQuery q = prepare_query("occluded", rays.size(), out.size(), options, true, s.layout,
                                    s.tlas_data(), s.data.empty() || s.empty_tlas());
  if (!q.fn) {
    std::fill(out.begin(), out.end(), uint8_t(0));
    return;
  }
  if (const Accel* direct = s.direct(); direct && ray_mask != 0) {
    kestrel::occluded(*direct, rays, out, options);
    return;
  }
  PacketChoice stream_choice;  // for a stream's sorted chunks, as the flat stream (trace.cpp)
  const auto run = [&](std::span<const Ray> r, const uint32_t* callers, size_t first) {
    InstanceHit local[stream_chunk];
    q.run(r, options, callers ? stream_choice : s.any_choice, callers != nullptr,
          [&](kernels::TlasFn fn) {
            fn(q.tlas, s.data.data(), r.data(), local, r.size(), ray_mask);
          });
    for (size_t j = 0; j < r.size(); ++j) out[callers ? callers[j] : first + j] = local[j].hit();
  };
  if (stream_by_default(rays, s.world, 0, true, false, options)) {  // any hit: only when asked
    for_each_stream_chunk(rays, s.world, [&](const Ray* r, const uint32_t* callers, size_t n) {
      run(std::span<const Ray>(r, n), callers, 0);
    });
    return;
  }
  parallel_for(0, rays.size(), 1024, [&](size_t b, size_t e) {
    for (size_t i = b; i < e; i += stream_chunk)
      run(rays.subspan(i, std::min(stream_chunk, e - i)), nullptr, i);
  });
}

void InstancedScene::any_hits(std::span<const Ray> rays, std::span<InstanceHit> hits,
                              uint32_t ray_mask, const TraceOptions& options) const {
  const Impl& s = *impl_;
  const TlasQuery q = prepare_query("any_hits", rays.size(), hits.size(), options, true, s.layout,
                                    s.tlas_data(), s.data.empty() || s.empty_tlas());
  if (!q.fn) {
    for (InstanceHit& h : hits) h = InstanceHit{};
    return;
  }
  if (const Accel* direct = s.direct(); direct && ray_mask != 0) {
    thread_local std::vector<Hit> scratch;
    scratch.resize(rays.size());
    kestrel::trace(*direct, rays, std::span<Hit>(scratch.data(), rays.size()), true, options);
    const Hit* found = scratch.data();
    parallel_for(0, rays.size(), 16384, [&](size_t b, size_t e) {
      for (size_t i = b; i < e; ++i) {
        const Hit& h = found[i];
        hits[i] = h.hit() ? InstanceHit{h.t, h.prim_id, s.direct_id, 0, 0} : InstanceHit{};
      }
    });
    return;
  }
  parallel_for(0, rays.size(), 1024, [&](size_t b, size_t e) {
    for (size_t i = b; i < e; i += stream_chunk) {
      const auto chunk = rays.subspan(i, std::min(stream_chunk, e - i));
      q.run(chunk, options, s.any_choice, false, [&](kernels::TlasFn fn) {
        fn(q.tlas, s.data.data(), chunk.data(), hits.data() + i, chunk.size(), ray_mask);
      });
    }
  });
}

void InstancedScene::set_materials(std::vector<Material> materials, std::vector<Texture> textures) {
  impl_->materials = std::move(materials);
  impl_->textures = std::move(textures);
}
const std::vector<Material>& InstancedScene::materials() const {
  return impl_->materials;
}
const std::vector<Texture>& InstancedScene::textures() const {
  return impl_->textures;
}
void InstancedScene::set_lights(std::vector<Light> lights) {
  impl_->lights = std::move(lights);
}
const std::vector<Light>& InstancedScene::lights() const {
  return impl_->lights;
}
void InstancedScene::set_source(std::string source) {
  impl_->source = std::move(source);
}
const std::string& InstancedScene::source() const {
  return impl_->source;
}
uint64_t InstancedScene::generation() const {
  return impl_->generation;
}

ValidationReport InstancedScene::validation() const {
  ValidationReport r;
  for (const auto& m : impl_->meshes) {
    if (!m.live || !m.built) continue;
    const ValidationReport& v = m.blas.validation.report;
    r.triangle_count += v.triangle_count;
    r.valid_triangle_count += v.valid_triangle_count;
    r.nonfinite_triangle_count += v.nonfinite_triangle_count;
    r.bad_index_triangle_count += v.bad_index_triangle_count;
    r.degenerate_triangle_count += v.degenerate_triangle_count;
    r.empty_mesh_count += v.empty_mesh_count;
  }
  return r;
}

size_t InstancedScene::instance_count() const {
  size_t n = 0;
  for (const auto& i : impl_->instances) n += i.live;
  return n;
}

size_t InstancedScene::mesh_count() const {
  size_t n = 0;
  for (const auto& m : impl_->meshes) n += m.live;
  return n;
}

size_t InstancedScene::instance_capacity() const {
  return impl_->instances.size();
}
bool InstancedScene::has_instance(InstanceId id) const {
  return id < impl_->instances.size() && impl_->instances[id].live;
}
MeshId InstancedScene::instance_mesh(InstanceId id) const {
  return impl_->instance(id, "instance_mesh").mesh;
}
Affine3 InstancedScene::transform(InstanceId id) const {
  return impl_->instance(id, "transform").transform;
}
uint32_t InstancedScene::mask(InstanceId id) const {
  return impl_->instance(id, "mask").mask;
}
const TriangleMesh& InstancedScene::mesh(MeshId id) const {
  return impl_->mesh(id, "mesh").scene.meshes[0];
}

size_t InstancedScene::memory_bytes() const {
  size_t bytes = impl_->tlas4.size() * sizeof(Bvh4Node) + impl_->tlas8.size() * sizeof(Bvh8Node) +
                 impl_->data.size() * sizeof(kernels::InstanceData);
  for (const auto& m : impl_->meshes)
    if (m.live && m.built) bytes += m.blas.memory_bytes();
  return bytes;
}

Scene InstancedScene::flatten() const {
  Scene out;
  for (const auto& inst : impl_->instances) {
    if (!inst.live) continue;
    TriangleMesh m = impl_->meshes[inst.mesh].scene.meshes[0];
    for (Vec3& p : m.positions) p = inst.transform.point(p);
    out.meshes.push_back(std::move(m));
  }
  return out;
}

}  // namespace kestrel
