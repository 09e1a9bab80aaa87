// kestrel public API: what a loader returns. An Asset owns a material-carrying InstancedScene
// (the only scene kestrel renders) and whatever animates it; update(time) poses and commits.
#pragma once
#include <memory>
#include <string>
#include <vector>

#include "kestrel/instances.h"
#include "kestrel/scene.h"

namespace kestrel {

class Asset {
 public:
  /// An OBJ (+MTL), glTF / GLB or "builtin:NAME". OBJ and built-in scenes: one identity
  /// instance per mesh; glTF: a mesh per glTF mesh, an instance per node that uses one, and
  /// animation clip `clip` (GltfInstances). Committed at time 0, ready to render. Throws Error
  /// naming the file.
  static Asset load(const std::string& path, size_t clip = 0, SceneConfig config = {});
  /// A scene in memory: each mesh one identity instance; materials, textures and source
  /// moved in. Committed.
  static Asset from_scene(Scene scene, SceneConfig config = {});

  ~Asset();
  Asset(Asset&&) noexcept;
  Asset& operator=(Asset&&) noexcept;

  InstancedScene& scene();
  const InstancedScene& scene() const;
  /// Poses the scene at time t (seconds, wrapped into the animation's span) and commits.
  /// A static asset has nothing to pose: it commits only when asked to (`force`) — edits made
  /// through scene() are committed by the caller.
  CommitStats update(double time, bool force = false);
  /// Lights added to the file's own (e.g. a lights file): kept across update().
  void add_lights(const std::vector<Light>& lights);
  bool animated() const;
  /// End of the longest animation channel, seconds (0 when static).
  double duration() const;
  const std::string& source() const;
  /// Problems that did not stop the load (an undecodable texture, skipped primitives).
  const std::vector<std::string>& warnings() const;
  /// Triangles placed by the live instances (a mesh placed twice counts twice).
  size_t triangle_count() const;
  /// World bounds of every finite vertex a placed triangle uses, as of the last update.
  Bounds3 bounds() const;

 private:
  struct Impl;
  Asset();
  std::unique_ptr<Impl> impl_;
};

}  // namespace kestrel
