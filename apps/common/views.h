// Cameras for the tools: the framing view of any scene and the named views of
// ../shared/scenes/README.md (e.g. the inside-Sponza view).
#pragma once
#include <optional>
#include <string>

#include "kestrel/render.h"
#include "kestrel/trace.h"

namespace kestrel::tools {

/// A pinhole camera: eye, target, +Y up, vertical field of view in degrees.
struct PinholeCamera {
  Vec3 eye, target;
  float vfov_degrees = 45.0f;
  /// Ray through pixel (px, py) of a width x height image (py = 0 at the top), at the
  /// pixel's centre offset by (jx, jy) in [0, 1).
  Ray ray(int px, int py, int width, int height, float jx = 0.5f, float jy = 0.5f) const;
};

using kestrel::scene_bounds;

/// The framing view (kestrel::framing_camera): target the box centre, eye = target +
/// normalize(0.3, 0.35, -1) * r / sin(vfov / 2), r = half the box diagonal, vfov 45.
PinholeCamera framing_view(const Scene& scene);

/// A named view (kestrel::find_view: "framing" always exists, others from the scene's
/// views file or data/views, e.g. "inside" for Dabrovic Sponza). nullopt if unknown.
std::optional<PinholeCamera> named_view(const Scene& scene, const std::string& name);

/// A camera path: a keyframe JSON file (CameraPath::load), or "orbit[:DEGREES]" (default
/// 360), a turntable about start_camera_for(asset, view_name). Throws Error.
CameraPath camera_path_for(const Asset& asset, const std::string& path_spec,
                           const std::string& view_name);
/// A named view of a loaded scene (its .views.json or data/views); "" = "front", else
/// "framing". Throws Error for an unknown name.
Camera start_camera_for(const Asset& asset, const std::string& view_name);

}  // namespace kestrel::tools
