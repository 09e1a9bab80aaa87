// Asset: a file as the one scene model (a material-carrying InstancedScene) and its animation.
#include "kestrel/asset.h"

#include <fmt/format.h>

#include <cmath>
#include <optional>

#include "core/vec.h"
#include "io/loaders.h"
#include "kestrel/error.h"

namespace kestrel {

struct Asset::Impl {
  InstancedScene scene;
  std::optional<GltfInstances> gltf;
  std::string source;
  std::vector<std::string> warnings;
  std::vector<Light> own_lights, extra_lights;  // the file's, and add_lights()'s
  void apply_lights() {
    std::vector<Light> all = own_lights;
    all.insert(all.end(), extra_lights.begin(), extra_lights.end());
    scene.set_lights(std::move(all));
  }
  mutable Bounds3 bounds;
  mutable uint64_t bounds_generation = ~uint64_t(0);  // the scene generation `bounds` are of

  explicit Impl(SceneConfig config) : scene(config) {}

  // Bounds of every finite vertex of a placed, index-valid triangle (scene_bounds' rule).
  void update_bounds() const {
    if (bounds_generation == scene.generation()) return;
    bounds_generation = scene.generation();
    bounds = Bounds3{};
    for (InstanceId i = 0; i < scene.instance_capacity(); ++i) {
      if (!scene.has_instance(i) || scene.mask(i) == 0) continue;
      const TriangleMesh& m = scene.mesh(scene.instance_mesh(i));
      const Affine3 xf = scene.transform(i);
      const Affine3 identity;
      const bool is_identity = std::equal(std::begin(xf.m), std::end(xf.m), std::begin(identity.m));
      for (uint32_t index : m.indices) {
        if (index >= m.positions.size() || !is_finite(m.positions[index])) continue;
        extend(bounds, is_identity ? m.positions[index] : xf.point(m.positions[index]));
      }
    }
  }
  void warn_about_skipped_triangles() {
    const std::string w = skipped_triangles_warning(source, scene.validation());
    if (!w.empty()) warnings.push_back(w);
  }
};

Asset::Asset() = default;
Asset::~Asset() = default;
Asset::Asset(Asset&&) noexcept = default;
Asset& Asset::operator=(Asset&&) noexcept = default;

Asset Asset::from_scene(Scene scene, SceneConfig config) {
  Asset a;
  a.impl_ = std::make_unique<Impl>(config);
  Impl& m = *a.impl_;
  m.source = scene.source;
  m.warnings = std::move(scene.warnings);
  for (TriangleMesh& mesh : scene.meshes)
    m.scene.add_instance(m.scene.add_mesh(std::move(mesh)), Affine3{});
  m.scene.set_materials(std::move(scene.materials), std::move(scene.textures));
  m.own_lights = std::move(scene.lights);
  m.apply_lights();
  m.scene.set_source(m.source);
  m.scene.commit();
  return a;
}

Asset Asset::load(const std::string& path, size_t clip, SceneConfig config) {
  if (!is_gltf_path(path)) return from_scene(load_scene(path), config);
  Asset a;
  a.impl_ = std::make_unique<Impl>(config);
  Impl& m = *a.impl_;
  m.source = path;
  m.gltf.emplace(GltfInstances::load(path, clip));
  m.gltf->add_to(m.scene);
  m.scene.set_materials(m.gltf->materials(), m.gltf->textures());
  m.own_lights = m.gltf->lights();
  m.apply_lights();
  m.scene.set_source(path);
  m.scene.commit();
  m.warn_about_skipped_triangles();
  return a;
}

InstancedScene& Asset::scene() {
  return impl_->scene;
}
const InstancedScene& Asset::scene() const {
  return impl_->scene;
}
void Asset::add_lights(const std::vector<Light>& lights) {
  impl_->extra_lights.insert(impl_->extra_lights.end(), lights.begin(), lights.end());
  impl_->apply_lights();
}

bool Asset::animated() const {
  return impl_->gltf && impl_->gltf->duration() > 0;
}
double Asset::duration() const {
  return impl_->gltf ? impl_->gltf->duration() : 0.0;
}
const std::string& Asset::source() const {
  return impl_->source;
}
const std::vector<std::string>& Asset::warnings() const {
  return impl_->warnings;
}
Bounds3 Asset::bounds() const {
  impl_->update_bounds();
  return impl_->bounds;
}

CommitStats Asset::update(double time, bool force) {
  Impl& m = *impl_;
  if (!std::isfinite(time))
    throw Error(ErrorCode::invalid_argument,
                fmt::format("{}: time {} is not finite", m.source, time));
  if (!m.gltf && !force) return {};
  if (m.gltf) {
    m.gltf->set_time(m.scene, time);
    m.own_lights = m.gltf->lights();
    m.apply_lights();
  }
  return m.scene.commit();
}

size_t Asset::triangle_count() const {
  const InstancedScene& s = impl_->scene;
  size_t n = 0;
  for (InstanceId i = 0; i < s.instance_capacity(); ++i)
    if (s.has_instance(i)) n += s.mesh(s.instance_mesh(i)).triangle_count();
  return n;
}

}  // namespace kestrel
