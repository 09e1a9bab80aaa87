// Cameras, named views, keyframed camera paths and environment specs: the renderer's
// inputs that come from small JSON files or command-line strings.
#include <fmt/format.h>
#include <json.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "core/file_io.h"
#include "core/vec.h"
#include "io/loaders.h"
#include "kestrel/error.h"
#include "kestrel/render.h"

#ifndef KESTREL_DATA_DIR
#define KESTREL_DATA_DIR "data"
#endif

namespace kestrel {

namespace {

using nlohmann::json;

json read_json(const std::string& path) {
  const std::string text = read_bounded_file(path, uint64_t(64) << 20, "JSON file");
  try {
    return json::parse(text);
  } catch (const json::exception& e) {
    throw Error(ErrorCode::parse_error, fmt::format("{}: malformed JSON: {}", path, e.what()));
  }
}

Vec3 vec3_field(const std::string& path, const std::string& where, const json& obj,
                const char* key) {
  if (!obj.contains(key))
    throw Error(ErrorCode::parse_error, fmt::format("{}: {} has no \"{}\"", path, where, key));
  const json& v = obj[key];
  if (!v.is_array() || v.size() != 3 || !v[0].is_number() || !v[1].is_number() || !v[2].is_number())
    throw Error(ErrorCode::parse_error,
                fmt::format("{}: {}: \"{}\" must be an array of 3 numbers", path, where, key));
  // Bounded so the spline through the keys (squared distances, in float) stays finite.
  for (int k = 0; k < 3; ++k)
    if (!(std::fabs(v[k].get<double>()) <= 1e18))
      throw Error(ErrorCode::parse_error,
                  fmt::format("{}: {}: \"{}\" has a coordinate beyond 1e18 ({})", path, where, key,
                              v[k].dump()));
  return {v[0].get<float>(), v[1].get<float>(), v[2].get<float>()};
}

float number_field(const std::string& path, const std::string& where, const json& obj,
                   const char* key, float fallback) {
  if (!obj.contains(key)) return fallback;
  if (!obj[key].is_number())
    throw Error(ErrorCode::parse_error,
                fmt::format("{}: {}: \"{}\" must be a number", path, where, key));
  return obj[key].get<float>();
}

Camera camera_from_json(const std::string& path, const std::string& where, const json& obj) {
  if (!obj.is_object())
    throw Error(ErrorCode::parse_error, fmt::format("{}: {} must be an object", path, where));
  Camera c;
  c.eye = vec3_field(path, where, obj, "eye");
  c.target = vec3_field(path, where, obj, "target");
  c.vfov_degrees = number_field(path, where, obj, "vfov", 45.0f);
  c.aperture_radius = number_field(path, where, obj, "aperture", 0.0f);
  c.focus_distance = number_field(path, where, obj, "focus_distance", 0.0f);
  try {
    check_camera(c);
  } catch (const Error& e) {
    throw Error(ErrorCode::parse_error, fmt::format("{}: {}: {}", path, where, e.what()));
  }
  return c;
}

std::string scene_stem(const std::string& source) {
  if (source.rfind("builtin:", 0) == 0) return source.substr(8);
  return std::filesystem::path(source).stem().string();
}

Vec3 catmull_rom(Vec3 p0, Vec3 p1, Vec3 p2, Vec3 p3, float t) {
  // Centripetal parameterisation (alpha = 0.5), Barry-Goldman pyramid.
  auto knot = [](float ti, Vec3 a, Vec3 b) {
    return ti + std::max(std::sqrt(length(b - a)), 1e-4f);
  };
  const float t0 = 0, t1 = knot(t0, p0, p1), t2 = knot(t1, p1, p2), t3 = knot(t2, p2, p3);
  const float u = t1 + (t2 - t1) * t;
  auto lerp = [](Vec3 a, Vec3 b, float ta, float tb, float x) {
    return a * ((tb - x) / (tb - ta)) + b * ((x - ta) / (tb - ta));
  };
  const Vec3 a1 = lerp(p0, p1, t0, t1, u), a2 = lerp(p1, p2, t1, t2, u),
             a3 = lerp(p2, p3, t2, t3, u);
  const Vec3 b1 = lerp(a1, a2, t0, t2, u), b2 = lerp(a2, a3, t1, t3, u);
  return lerp(b1, b2, t1, t2, u);
}

}  // namespace

void check_camera(const Camera& c) {
  if (!is_finite(c.eye) || !is_finite(c.target))
    throw Error(ErrorCode::invalid_argument, "camera: eye and target must be finite");
  if (!(length(c.target - c.eye) > 0))
    throw Error(ErrorCode::invalid_argument, "camera: eye and target coincide");
  if (!(c.vfov_degrees > 0 && c.vfov_degrees < 180))
    throw Error(ErrorCode::invalid_argument,
                fmt::format("camera: vfov {} is not in (0, 180) degrees", c.vfov_degrees));
  if (!(c.aperture_radius >= 0 && std::isfinite(c.aperture_radius)) ||
      !(c.focus_distance >= 0 && std::isfinite(c.focus_distance)))
    throw Error(ErrorCode::invalid_argument,
                "camera: aperture and focus distance must be finite and >= 0");
}

Camera framing_camera(const Scene& scene) {
  return framing_camera(scene_bounds(scene));
}

Camera framing_camera(const Bounds3& b) {
  Camera cam;
  cam.vfov_degrees = 45.0f;
  cam.target = is_empty(b) ? Vec3{0, 0, 0} : center(b);
  const float r = is_empty(b) ? 1.0f : std::max(0.5f * length(extent(b)), 1e-6f);
  const float dist = r / std::sin(cam.vfov_degrees * 0.5f * 3.14159265358979f / 180.0f);
  cam.eye = cam.target + normalize(Vec3{0.3f, 0.35f, -1.0f}) * dist;
  return cam;
}

std::map<std::string, Camera> load_views(const std::string& path) {
  const json j = read_json(path);
  if (!j.is_object() || !j.contains("views") || !j["views"].is_object())
    throw Error(ErrorCode::parse_error,
                fmt::format("{}: expected an object with \"views\": {{NAME: {{...}}}}", path));
  std::map<std::string, Camera> views;
  for (const auto& [name, v] : j["views"].items())
    views[name] = camera_from_json(path, "view '" + name + "'", v);
  return views;
}

std::vector<std::string> view_files_for(const std::string& scene_path) {
  std::vector<std::string> files;
  if (scene_path.rfind("builtin:", 0) != 0) {
    std::filesystem::path p(scene_path);
    files.push_back((p.parent_path() / (p.stem().string() + ".views.json")).string());
  }
  files.push_back(std::string(KESTREL_DATA_DIR) + "/views/" + scene_stem(scene_path) +
                  ".views.json");
  return files;
}

namespace {
std::optional<Camera> find_view(const std::string& source, const Bounds3& bounds,
                                const std::string& name) {
  if (name.empty() || name == "framing") return framing_camera(bounds);
  for (const std::string& file : view_files_for(source)) {
    if (!std::filesystem::is_regular_file(file)) continue;
    const auto views = load_views(file);
    if (auto it = views.find(name); it != views.end()) return it->second;
  }
  return std::nullopt;
}
}  // namespace

std::optional<Camera> find_view(const Scene& scene, const std::string& name) {
  if (name.empty() || name == "framing") return framing_camera(scene);
  return find_view(scene.source, Bounds3{}, name);
}

std::optional<Camera> find_view(const Asset& asset, const std::string& name) {
  return find_view(asset.source(), asset.bounds(), name);
}

CameraPath CameraPath::load(const std::string& path) {
  const json j = read_json(path);
  if (!j.is_object() || !j.contains("keyframes") || !j["keyframes"].is_array() ||
      j["keyframes"].empty())
    throw Error(ErrorCode::parse_error,
                fmt::format("{}: expected an object with a non-empty \"keyframes\" array", path));
  CameraPath out;
  for (size_t i = 0; i < j["keyframes"].size(); ++i) {
    const json& k = j["keyframes"][i];
    const std::string where = fmt::format("keyframe {}", i);
    Key key;
    key.camera = camera_from_json(path, where, k);
    if (!k.contains("time") || !k["time"].is_number())
      throw Error(ErrorCode::parse_error,
                  fmt::format("{}: {} has no numeric \"time\"", path, where));
    key.time = k["time"].get<double>();
    if (!(std::fabs(key.time) <= 1e9) ||
        (!out.keys.empty() && !(key.time >= out.keys.back().time + 1e-6)))
      throw Error(
          ErrorCode::parse_error,
          fmt::format(
              "{}: {}: time {}: times must be increasing (by at least 1e-6 s) and within +-1e9 s",
              path, where, k["time"].dump()));
    out.keys.push_back(key);
  }
  return out;
}

CameraPath CameraPath::orbit(const Camera& start, double degrees, double seconds) {
  check_camera(start);
  if (!std::isfinite(degrees) || !std::isfinite(seconds) || !(seconds > 0) ||
      std::abs(degrees) > 3600)
    throw Error(
        ErrorCode::invalid_argument,
        fmt::format("orbit: expected finite degrees (|d| <= 3600) and seconds > 0, got {} and {}",
                    degrees, seconds));
  const int steps = std::max(1, int(std::ceil(std::abs(degrees) / 15.0)));
  CameraPath out;
  const Vec3 arm = start.eye - start.target;
  for (int i = 0; i <= steps; ++i) {
    const double a = degrees * double(i) / double(steps) * 3.14159265358979 / 180.0;
    const float c = float(std::cos(a)), s = float(std::sin(a));
    Key key;
    key.time = seconds * double(i) / double(steps);
    key.camera = start;
    key.camera.eye = start.target + Vec3{c * arm.x + s * arm.z, arm.y, -s * arm.x + c * arm.z};
    out.keys.push_back(key);
  }
  return out;
}

Camera CameraPath::at(double time) const {
  if (keys.empty()) throw Error(ErrorCode::invalid_argument, "camera path has no keyframes");
  if (keys.size() == 1 || time <= keys.front().time) return keys.front().camera;
  if (time >= keys.back().time) return keys.back().camera;
  size_t i = 0;
  while (i + 2 < keys.size() && keys[i + 1].time <= time) ++i;
  const Key& k1 = keys[i];
  const Key& k2 = keys[i + 1];
  const float t = float((time - k1.time) / (k2.time - k1.time));
  const Camera& c0 = keys[i > 0 ? i - 1 : i].camera;
  const Camera& c3 = keys[i + 2 < keys.size() ? i + 2 : i + 1].camera;
  Camera c;
  // End segments repeat their end key as the outer control point: extrapolate it instead,
  // so the curve keeps its tangent.
  auto outer = [](Vec3 inner, Vec3 end, bool real, Vec3 given) {
    return real ? given : end + (end - inner);
  };
  const Vec3 e0 = outer(k2.camera.eye, k1.camera.eye, i > 0, c0.eye);
  const Vec3 e3 = outer(k1.camera.eye, k2.camera.eye, i + 2 < keys.size(), c3.eye);
  const Vec3 t0 = outer(k2.camera.target, k1.camera.target, i > 0, c0.target);
  const Vec3 t3 = outer(k1.camera.target, k2.camera.target, i + 2 < keys.size(), c3.target);
  c.eye = catmull_rom(e0, k1.camera.eye, k2.camera.eye, e3, t);
  c.target = catmull_rom(t0, k1.camera.target, k2.camera.target, t3, t);
  auto lerp = [t](float a, float b) { return a + (b - a) * t; };
  c.vfov_degrees = lerp(k1.camera.vfov_degrees, k2.camera.vfov_degrees);
  c.aperture_radius = lerp(k1.camera.aperture_radius, k2.camera.aperture_radius);
  c.focus_distance = lerp(k1.camera.focus_distance, k2.camera.focus_distance);
  return c;
}

Environment Environment::parse(const std::string& spec) {
  Environment env;
  if (spec == "none") return env;
  if (spec == "sky") {
    env.color = {1.0f, 1.0f, 1.0f};
    env.overcast = true;
    return env;
  }
  std::string values = spec.rfind("constant:", 0) == 0 ? spec.substr(9) : spec;
  float r, g, b;
  char c1, c2;
  int consumed = 0;
  if (std::sscanf(values.c_str(), "%f %c %f %c %f%n", &r, &c1, &g, &c2, &b, &consumed) == 5 &&
      c1 == ',' && c2 == ',' && size_t(consumed) == values.size()) {
    if (!(std::isfinite(r) && std::isfinite(g) && std::isfinite(b) && r >= 0 && g >= 0 && b >= 0))
      throw Error(ErrorCode::invalid_argument,
                  fmt::format("environment '{}': radiance must be finite and >= 0", spec));
    env.color = {r, g, b};
    return env;
  }
  if (spec.rfind("constant:", 0) == 0)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("environment '{}': expected constant:R,G,B", spec));
  env.image = read_float_image(spec);
  if (env.image.channels != 3) {
    FloatImage rgb(env.image.width, env.image.height, 3);
    for (int y = 0; y < rgb.height; ++y)
      for (int x = 0; x < rgb.width; ++x)
        for (int c = 0; c < 3; ++c)
          rgb.at(x, y)[c] = env.image.at(x, y)[std::min(c, env.image.channels - 1)];
    env.image = std::move(rgb);
  }
  for (float& v : env.image.pixels)
    if (!std::isfinite(v) || v < 0)
      throw Error(ErrorCode::parse_error,
                  fmt::format("{}: environment has a negative, NaN or Inf pixel", spec));
  return env;
}

}  // namespace kestrel
