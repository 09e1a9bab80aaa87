// kestrel public API: two-level scenes. Meshes get their own BVH (BLAS); instances place a
// mesh with an affine transform and a mask; commit() builds new BLASes, refits or rebuilds
// changed ones and rebuilds the top-level BVH (TLAS) over the instances. Rays are traced in
// world space; each instance's BLAS sees the ray in its object space.
#pragma once
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "kestrel/scene.h"
#include "kestrel/trace.h"

namespace kestrel {

/// Affine transform, row-major 3 x 4: p' = (m0 p.x + m1 p.y + m2 p.z + m3, m4.. + m7, m8.. + m11).
struct Affine3 {
  float m[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
  static Affine3 translation(Vec3 t);
  static Affine3 scaling(Vec3 s);
  static Affine3 rotation_y(float degrees);
  /// This transform applied after b.
  Affine3 operator*(const Affine3& b) const;
  Vec3 point(Vec3 p) const;
  Vec3 vector(Vec3 v) const;
};

/// Why a transform cannot place an instance ("" when it can): a NaN/Inf entry, or a
/// singular (or nearly singular, |det| < 1e-12 of its scale) linear part.
std::string transform_problem(const Affine3& a);
/// Inverse of an invertible transform; throws Error(invalid_argument) otherwise.
Affine3 inverse(const Affine3& a);

using MeshId = uint32_t;
using InstanceId = uint32_t;

/// A hit in a two-level scene: t along the world ray (units of its dir), the triangle's
/// index in its mesh, the instance, and the barycentrics.
struct InstanceHit {
  float t = std::numeric_limits<float>::infinity();
  uint32_t prim_id = invalid_id;
  uint32_t instance_id = invalid_id;
  float u = 0, v = 0;
  bool hit() const { return instance_id != invalid_id; }
};

struct SceneConfig {
  BuildConfig blas;        ///< how meshes are built (layout: automatic)
  BuildConfig tlas = [] {  ///< how the instance tree is built (LBVH: built every frame)
    BuildConfig c;
    c.builder = Builder::lbvh;
    c.max_leaf_size = 1;
    return c;
  }();
  /// A deformed mesh is refitted while its BVH's SAH cost stays within this factor of the
  /// cost right after its last full build; beyond it, the mesh is rebuilt.
  float refit_sah_factor = 1.5f;
};

/// What commit() did and how long it took (wall clock, ms).
struct CommitStats {
  double total_ms = 0, tlas_ms = 0, blas_build_ms = 0, blas_refit_ms = 0;
  size_t blas_builds = 0, blas_refits = 0, instances = 0;
};

/// The scene kestrel renders: meshes (each its own BLAS) placed by instances (the TLAS), with
/// the materials and textures the meshes' material_ids index. A file becomes one through
/// Asset::load (kestrel/asset.h): an OBJ as one identity instance per mesh, a glTF as its node
/// instances. A scene of one identity instance is traced through its BLAS directly (the same
/// hits and speed as the single-level Accel).
class InstancedScene {
 public:
  explicit InstancedScene(SceneConfig config = {});
  ~InstancedScene();
  InstancedScene(InstancedScene&&) noexcept;
  InstancedScene& operator=(InstancedScene&&) noexcept;

  /// Adds a mesh (world-independent object space). Validated and built at commit().
  MeshId add_mesh(TriangleMesh mesh);
  /// Places a mesh. Throws Error for an unknown mesh or a transform_problem().
  InstanceId add_instance(MeshId mesh, const Affine3& transform, uint32_t mask = 0xFFFFFFFFu);
  void set_transform(InstanceId instance, const Affine3& transform);
  void set_mask(InstanceId instance, uint32_t mask);
  /// New vertex positions for a mesh (same count; the triangles are kept): refit or rebuild
  /// at the next commit(). `normals`: new vertex normals too (where the mesh has as many).
  void update_vertices(MeshId mesh, std::span<const Vec3> positions,
                       std::span<const Vec3> normals = {});
  void remove_instance(InstanceId instance);
  /// Throws Error while an instance still uses the mesh.
  void remove_mesh(MeshId mesh);

  /// What the meshes' material_ids index, and the textures the materials name. Take effect
  /// at the next commit().
  void set_materials(std::vector<Material> materials, std::vector<Texture> textures = {});
  const std::vector<Material>& materials() const;
  const std::vector<Texture>& textures() const;
  /// Punctual lights, in world space (checked by the renderer: light_problem()).
  void set_lights(std::vector<Light> lights);
  const std::vector<Light>& lights() const;
  /// Where the scene came from (a file, "builtin:NAME"): errors of the renderer name it.
  void set_source(std::string source);
  const std::string& source() const;
  /// Builds what changed; queries see the scene as of the last commit().
  CommitStats commit();
  /// Commits so far: what a Renderer compares to see that the scene moved.
  uint64_t generation() const;
  /// Triangle validation summed over the committed meshes (each counted once).
  ValidationReport validation() const;

  /// Closest hits of a batch (threads, chunks; instance masks AND ray_mask must be non-zero).
  /// Coherent runs may go as lane packets through the TLAS and each BLAS (Bvh8 layout): where
  /// options.packets is unset, the scene times runs each way and takes the faster until a BLAS
  /// is rebuilt. The hits are the same either way.
  void trace(std::span<const Ray> rays, std::span<InstanceHit> hits,
             uint32_t ray_mask = 0xFFFFFFFFu, const TraceOptions& options = {}) const;
  /// Occlusion of a batch: 1 when the ray hits anything in (tmin, tmax).
  void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded,
                uint32_t ray_mask = 0xFFFFFFFFu, const TraceOptions& options = {}) const;
  /// What occluded() decides from: for each ray a hit in (tmin, tmax) and its triangle — any
  /// one, not necessarily the closest (u = v = 0) — or a miss. For callers that filter what
  /// blocks a ray (the renderer's cut-outs).
  void any_hits(std::span<const Ray> rays, std::span<InstanceHit> hits,
                uint32_t ray_mask = 0xFFFFFFFFu, const TraceOptions& options = {}) const;

  size_t instance_count() const;
  size_t mesh_count() const;
  /// One past the largest instance id handed out (ids of removed instances stay unused).
  size_t instance_capacity() const;
  /// Whether an instance exists (not removed).
  bool has_instance(InstanceId instance) const;
  /// The mesh an instance places, its transform and mask (Error for an unknown instance).
  MeshId instance_mesh(InstanceId instance) const;
  Affine3 transform(InstanceId instance) const;
  uint32_t mask(InstanceId instance) const;
  /// A mesh as last given (positions as of the last update_vertices); Error if unknown.
  const TriangleMesh& mesh(MeshId mesh) const;
  /// Bytes of every BLAS and the TLAS as committed.
  size_t memory_bytes() const;
  /// The committed scene flattened into one Scene: one mesh per instance, vertices in world
  /// space, in instance-id order (for comparisons and tests).
  Scene flatten() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// A glTF 2.0 file as a two-level scene: every glTF mesh (its triangle primitives, in object
/// space) becomes one mesh, every node that references a mesh one instance, placed by the
/// node hierarchy, so a mesh used by several nodes is built once. One animation clip's node
/// channels (translation / rotation / scale; LINEAR, STEP and CUBICSPLINE samplers) and
/// morph-target weights drive set_time(). Skins are not applied (skinned meshes stay in
/// their bind pose); a morphing mesh follows the weights of the first node using it.
class GltfInstances {
 public:
  /// Throws Error naming the file for an unreadable or inconsistent glTF. `clip`: which
  /// animation plays (clips may drive the same targets).
  static GltfInstances load(const std::string& path, size_t clip = 0);
  ~GltfInstances();
  GltfInstances(GltfInstances&&) noexcept;
  GltfInstances& operator=(GltfInstances&&) noexcept;

  size_t mesh_count() const;
  size_t instance_count() const;
  /// The file's materials (plus a trailing "default" one) and textures: the meshes'
  /// material_ids index these.
  const std::vector<Material>& materials() const;
  const std::vector<Texture>& textures() const;
  /// The file's KHR_lights_punctual lights placed by their nodes, as posed by the last
  /// add_to() / set_time() (a light under an animated node moves with it).
  const std::vector<Light>& lights() const;
  /// End of the longest animation channel, seconds (0 when nothing is animated).
  double duration() const;
  /// Adds the meshes and instances to a scene, posed at t = 0.
  void add_to(InstancedScene& scene);
  /// Poses the scene (added with add_to) at time t, wrapped into [0, duration): transforms
  /// of animated nodes and their descendants, vertices of meshes whose morph weights move.
  /// A node scaled to zero hides its instances (mask 0) until it is visible again.
  void set_time(InstancedScene& scene, double t);

 private:
  struct Impl;
  GltfInstances();
  std::unique_ptr<Impl> impl_;
};

/// Reads an instances file: '#' comments, then one instance per line,
/// "sx sy sz tx ty tz rot_y_deg" meaning p_world = R_y(rot_y_deg) * (s * p) + t
/// (../shared/scenes/bunny_grid/bunny_grid.instances.txt). Errors name the file and line.
std::vector<Affine3> load_instance_transforms(const std::string& path);

}  // namespace kestrel
