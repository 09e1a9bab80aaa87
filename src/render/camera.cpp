// Cameras, named views, keyframed camera paths and environment specs: the renderer's
// inputs that come from small JSON files or command-line strings.
#include <fmt/format.h>
#include <json.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>

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
  const Vec3 dir = normalize(Vec3{0.3f, 0.35f, -1.0f});
  cam.eye = cam.target + dir * dist;
  if (is_finite(cam.eye) && is_finite(cam.target)) return cam;
  // Finite bounds near the float limit: the centre and radius overflow in float; in double,
  // the eye either fits in float or no camera outside the bounds can be written down.
  double centre[3], sq = 0;
  for (int a = 0; a < 3; ++a) {
    const double lo = (&b.lo.x)[a], hi = (&b.hi.x)[a];
    centre[a] = 0.5 * (lo + hi);
    sq += 0.25 * (hi - lo) * (hi - lo);
  }
  const double far =
      std::sqrt(sq) / std::sin(double(cam.vfov_degrees) * 0.5 * 3.14159265358979 / 180.0);
  const double eye[3] = {centre[0] + dir.x * far, centre[1] + dir.y * far, centre[2] + dir.z * far};
  for (double e : eye)
    if (!(std::fabs(e) <= double(std::numeric_limits<float>::max())))
      throw Error(ErrorCode::invalid_argument,
                  fmt::format("camera: the scene's bounds ({}, {}, {}) .. ({}, {}, {}) are too "
                              "large to frame from outside in float; give a view (--view or a "
                              "views file)",
                              b.lo.x, b.lo.y, b.lo.z, b.hi.x, b.hi.y, b.hi.z));
  cam.target = {float(centre[0]), float(centre[1]), float(centre[2])};
  cam.eye = {float(eye[0]), float(eye[1]), float(eye[2])};
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

std::optional<SceneLighting> suggested_lighting(const std::string& scene_path) {
  for (const std::string& file : view_files_for(scene_path)) {
    if (!std::filesystem::is_regular_file(file)) continue;
    const json j = read_json(file);
    if (!j.is_object() || !j.contains("lighting")) continue;
    const json& l = j["lighting"];
    auto bad = [&](const char* what) {
      return Error(ErrorCode::parse_error, fmt::format("{}: \"lighting\": {}", file, what));
    };
    if (!l.is_object()) throw bad("expected an object {\"env\", \"sun\", \"sky\"}");
    SceneLighting out;
    for (const auto& [key, v] : l.items()) {
      if (key == "env" || key == "sun") {
        if (!v.is_string()) throw bad("\"env\" and \"sun\" must be strings");
        (key == "env" ? out.env : out.sun) = v.get<std::string>();
      } else if (key == "sky") {
        if (!v.is_boolean()) throw bad("\"sky\" must be true or false");
        out.sky = v.get<bool>();
      } else {
        throw bad(("unknown key '" + key + "'").c_str());
      }
    }
    try {
      make_lighting(out.env, out.sun, out.sky);  // the specs are valid
    } catch (const Error& e) {
      throw Error(e.code(), fmt::format("{}: \"lighting\": {}", file, e.what()));
    }
    return out;
  }
  return std::nullopt;
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

// ---- the sun and the physical sky ------------------------------------------------------------

namespace kestrel {

void Sun::check() const {
  const float len = length(direction);
  if (!is_finite(direction) || !(len > 0) || !is_finite(irradiance) || irradiance.x < 0 ||
      irradiance.y < 0 || irradiance.z < 0 || !std::isfinite(angular_radius_degrees) ||
      !(angular_radius_degrees > 0) || angular_radius_degrees > 45)
    throw Error(ErrorCode::invalid_argument,
                "sun: direction must be finite and non-zero, irradiance finite and >= 0, angular "
                "radius in (0, 45] "
                "degrees");
}

Sun Sun::parse(const std::string& spec) {
  std::vector<float> v;
  size_t at = 0;
  while (at <= spec.size()) {
    const size_t comma = spec.find(',', at);
    const std::string part =
        spec.substr(at, comma == std::string::npos ? std::string::npos : comma - at);
    char* end = nullptr;
    const float x = std::strtof(part.c_str(), &end);
    if (part.empty() || end != part.c_str() + part.size() || !std::isfinite(x))
      throw Error(ErrorCode::invalid_argument,
                  fmt::format("--sun '{}': '{}' is not a finite number", spec, part));
    v.push_back(x);
    if (comma == std::string::npos) break;
    at = comma + 1;
  }
  if (v.size() != 2 && v.size() != 3)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("--sun '{}': expected AZIMUTH,ELEVATION[,INTENSITY]", spec));
  if (v[1] < -90 || v[1] > 90)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("--sun '{}': elevation {} is not in [-90, 90]", spec, v[1]));
  if (v.size() == 3 && v[2] < 0)
    throw Error(ErrorCode::invalid_argument,
                fmt::format("--sun '{}': intensity {} is negative", spec, v[2]));
  const double az = double(v[0]) * 3.14159265358979 / 180.0,
               el = double(v[1]) * 3.14159265358979 / 180.0;
  Sun sun;
  sun.direction = {float(std::sin(az) * std::cos(el)), float(std::sin(el)),
                   float(-std::cos(az) * std::cos(el))};
  const float intensity = v.size() == 3 ? v[2] : 10.0f;
  sun.irradiance = {intensity, intensity, intensity};
  return sun;
}

namespace {

// Preetham et al. 1999: the Perez function and the zenith values of Y (kcd/m^2), x and y.
struct Perez {
  double a, b, c, d, e;
  double operator()(double cos_theta, double gamma, double cos_gamma) const {
    return (1 + a * std::exp(b / std::max(cos_theta, 0.01))) *
           (1 + c * std::exp(d * gamma) + e * cos_gamma * cos_gamma);
  }
};

struct PreethamSky {
  Perez Y, x, y;
  double zenith_Y, zenith_x, zenith_y, theta_s;
  explicit PreethamSky(double T, double theta_sun) : theta_s(theta_sun) {
    Y = {0.1787 * T - 1.4630, -0.3554 * T + 0.4275, -0.0227 * T + 5.3251, 0.1206 * T - 2.5771,
         -0.0670 * T + 0.3703};
    x = {-0.0193 * T - 0.2592, -0.0665 * T + 0.0008, -0.0004 * T + 0.2125, -0.0641 * T - 0.8989,
         -0.0033 * T + 0.0452};
    y = {-0.0167 * T - 0.2608, -0.0950 * T + 0.0092, -0.0079 * T + 0.2102, -0.0441 * T - 1.6537,
         -0.0109 * T + 0.0529};
    const double chi = (4.0 / 9.0 - T / 120.0) * (3.14159265358979 - 2 * theta_s);
    zenith_Y = std::max(0.0, (4.0453 * T - 4.9710) * std::tan(chi) - 0.2155 * T + 2.4192);
    const double t = theta_s, t2 = t * t, t3 = t2 * t;
    zenith_x = T * T * (0.00166 * t3 - 0.00375 * t2 + 0.00209 * t) +
               T * (-0.02903 * t3 + 0.06377 * t2 - 0.03202 * t + 0.00394) +
               (0.11693 * t3 - 0.21196 * t2 + 0.06052 * t + 0.25886);
    zenith_y = T * T * (0.00275 * t3 - 0.00610 * t2 + 0.00317 * t) +
               T * (-0.04214 * t3 + 0.08970 * t2 - 0.04153 * t + 0.00516) +
               (0.15346 * t3 - 0.26756 * t2 + 0.06670 * t + 0.26688);
  }
  // Linear sRGB radiance towards direction d (unit) with the sun towards s (unit), in kcd/m^2.
  Vec3 radiance(Vec3 d, Vec3 s) const {
    const double cos_theta = std::max(double(d.y), 0.0);
    const double cos_gamma = std::clamp(double(dot(d, s)), -1.0, 1.0), gamma = std::acos(cos_gamma);
    const double cs = std::cos(theta_s);
    const double Yv = zenith_Y * Y(cos_theta, gamma, cos_gamma) / Y(1.0, theta_s, cs);
    const double xv = zenith_x * x(cos_theta, gamma, cos_gamma) / x(1.0, theta_s, cs);
    const double yv = zenith_y * y(cos_theta, gamma, cos_gamma) / y(1.0, theta_s, cs);
    if (!(yv > 1e-6) || !(Yv > 0)) return {0, 0, 0};
    const double X = xv * Yv / yv, Z = (1 - xv - yv) * Yv / yv;
    const double r = 3.2406 * X - 1.5372 * Yv - 0.4986 * Z,
                 g = -0.9689 * X + 1.8758 * Yv + 0.0415 * Z,
                 b = 0.0557 * X - 0.2040 * Yv + 1.0570 * Z;
    return {float(std::max(r, 0.0)), float(std::max(g, 0.0)), float(std::max(b, 0.0))};
  }
};

}  // namespace

Environment Environment::physical_sky(const Sun& sun, float turbidity) {
  sun.check();
  if (!(turbidity >= 1.7f && turbidity <= 10.0f))
    throw Error(ErrorCode::invalid_argument,
                fmt::format("sky: turbidity {} is not in [1.7, 10]", turbidity));
  const Vec3 s = normalize(sun.direction);
  // Preetham's fit holds for the sun above the horizon: below it, the sky of a sun on it.
  const double theta_s =
      std::min(std::acos(std::clamp(double(s.y), -1.0, 1.0)), 1.5707963267948966 - 1e-3);
  const double horizontal = std::sqrt(double(s.x) * s.x + double(s.z) * s.z);
  const Vec3 s_fit =
      horizontal > 1e-9
          ? Vec3{float(s.x / horizontal * std::sin(theta_s)), float(std::cos(theta_s)),
                 float(s.z / horizontal * std::sin(theta_s))}
          : Vec3{0, float(std::cos(theta_s)), float(-std::sin(theta_s))};
  const PreethamSky sky(turbidity, theta_s);
  const double norm = 1.0 / PreethamSky(3.0, 3.14159265358979 / 4).zenith_Y;
  Environment env;
  env.sun = sun;
  env.cosine_sampled = true;  // smooth: see Environment::cosine_sampled
  const int w = 512, h = 256;
  env.image = FloatImage(w, h, 3);
  for (int y = 0; y < h; ++y) {
    const float v = (float(y) + 0.5f) / float(h), theta = v * 3.14159265f;
    for (int x = 0; x < w; ++x) {
      const float u = (float(x) + 0.5f) / float(w), phi = (u - 0.5f) * 2 * 3.14159265f;
      Vec3 d{std::sin(theta) * std::sin(phi), std::cos(theta), -std::sin(theta) * std::cos(phi)};
      float k = 1.0f;
      if (d.y < 0.0f)
        d = normalize(Vec3{d.x, 0.0f, d.z} + Vec3{0, 1e-3f, 0}), k = 0.1f;  // the ground
      const Vec3 r = sky.radiance(d, s_fit) * float(norm * k);
      float* p = env.image.at(x, y);
      p[0] = r.x, p[1] = r.y, p[2] = r.z;
    }
  }
  return env;
}

std::vector<Light> load_lights(const std::string& path) {
  const json j = read_json(path);
  if (!j.is_object() || !j.contains("lights") || !j["lights"].is_array())
    throw Error(ErrorCode::parse_error,
                fmt::format("{}: expected an object with a \"lights\" array", path));
  std::vector<Light> out;
  for (size_t i = 0; i < j["lights"].size(); ++i) {
    const json& o = j["lights"][i];
    const std::string where = fmt::format("light {}", i);
    if (!o.is_object())
      throw Error(ErrorCode::parse_error, fmt::format("{}: {} is not an object", path, where));
    Light l;
    l.name = o.contains("name") && o["name"].is_string() ? o["name"].get<std::string>()
                                                         : fmt::format("light{}", i);
    const std::string type =
        o.contains("type") && o["type"].is_string() ? o["type"].get<std::string>() : "point";
    if (type == "point")
      l.type = Light::Type::point;
    else if (type == "spot")
      l.type = Light::Type::spot;
    else if (type == "directional")
      l.type = Light::Type::directional;
    else
      throw Error(ErrorCode::parse_error,
                  fmt::format("{}: {} '{}': unknown type '{}' (expected point, spot or "
                              "directional)",
                              path, where, l.name, type));
    if (o.contains("position")) l.position = vec3_field(path, where, o, "position");
    if (o.contains("direction")) {
      const Vec3 d = vec3_field(path, where, o, "direction");
      l.direction = length(d) > 0 ? normalize(d) : d;
    }
    if (o.contains("color")) l.color = vec3_field(path, where, o, "color");
    l.intensity = number_field(path, where, o, "intensity", l.intensity);
    l.range = number_field(path, where, o, "range", l.range);
    l.inner_cone = number_field(path, where, o, "inner_cone", l.inner_cone);
    l.outer_cone = number_field(path, where, o, "outer_cone", l.outer_cone);
    if (const std::string p = light_problem(l); !p.empty())
      throw Error(ErrorCode::parse_error, fmt::format("{}: {} '{}': {}", path, where, l.name, p));
    out.push_back(l);
  }
  return out;
}

std::optional<Environment> make_lighting(const std::string& env, const std::string& sun, bool sky) {
  if (sun.empty() && !sky)
    return env.empty() ? std::nullopt : std::optional(Environment::parse(env));
  if (sky && !env.empty())
    throw Error(ErrorCode::invalid_argument, "give --sky or --env, not both");
  const Sun s = sun.empty() ? Sun{} : Sun::parse(sun);
  Environment e = env.empty() ? Environment::physical_sky(s) : Environment::parse(env);
  e.sun = s;
  return e;
}

}  // namespace kestrel
