// Python bindings of rendering and reconstruction: cameras and camera paths, the path tracer
// (every AOV as a float32 (H, W, C) array over the frame's own memory), the denoisers and
// upsamplers (one frame, or a sequence with state), and the real-time Pipeline stepped
// frame by frame.
#include <fmt/format.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <cmath>
#include <cstring>

#include "arrays.h"
#include "bindings.h"
#include "kestrel/asset.h"
#include "kestrel/denoise.h"
#include "kestrel/error.h"
#include "kestrel/pipeline.h"
#include "kestrel/render.h"
#include "kestrel/upscale.h"

namespace kestrel::python {

namespace {

py::tuple vec3_tuple(Vec3 v) {
  return py::make_tuple(v.x, v.y, v.z);
}

std::pair<int, int> resolution(py::handle res) {
  std::pair<int, int> wh;
  try {
    wh = res.cast<std::pair<int, int>>();
  } catch (const py::cast_error&) {
    throw py::type_error("res: expected (width, height)");
  }
  if (wh.first <= 0 || wh.second <= 0 || wh.first > 65536 || wh.second > 65536)
    throw py::value_error(fmt::format("res: {}x{} is not in 1..65536", wh.first, wh.second));
  return wh;
}

py::dict stats_dict(const RenderStats& s) {
  py::dict d;
  d["ms"] = s.ms;
  d["trace_ms"] = s.trace_ms;
  d["camera_rays"] = s.camera_rays;
  d["bounce_rays"] = s.bounce_rays;
  d["shadow_rays"] = s.shadow_rays;
  d["passes"] = s.passes;
  // Where the wall time went, by step (RenderStats::Steps, ms).
  py::dict steps;
  for (const auto& [name, m] : RenderStats::Steps::fields()) steps[name] = s.steps.*m;
  d["steps"] = steps;
  return d;
}

// A frame's AOVs as numpy arrays that own the frame's pixels (moved, not copied).
py::dict frame_dict(Frame&& frame) {
  py::dict d;
  for (int a = 0; a < aov_count; ++a) d[aov_name(Aov(a))] = take_image(std::move(frame.aov[a]));
  return d;
}

struct PyRenderer {
  std::optional<Asset> asset;                   // a Scene given: its copy as the one scene model
  std::shared_ptr<PyInstancedScene> instanced;  // an InstancedScene given: kept alive, referenced
  std::unique_ptr<Renderer> renderer;
  RenderStats last_stats;
  float jitter_x = 0.5f, jitter_y = 0.5f;
};

DenoiserOptions denoiser_options(const std::string& method, const std::string& weights,
                                 bool recurrent, bool bf16 = true) {
  DenoiserOptions o;
  auto m = denoise_method_from_name(method);
  if (!m)
    throw py::value_error(
        fmt::format("method: unknown denoiser '{}' (neural, svgf, atrous, rae)", method));
  o.method = *m;
  o.weights = weights;
  o.recurrent = recurrent;
  o.bf16 = bf16;
  return o;
}

UpscalerOptions upscaler_options(const std::string& method, int factor, const std::string& weights,
                                 bool bf16 = true) {
  UpscalerOptions o;
  o.bf16 = bf16;
  auto m = upscale_method_from_name(method);
  if (!m)
    throw py::value_error(
        fmt::format("method: unknown upsampler '{}' ({})", method, upscale_method_list()));
  if (factor != 2 && factor != 4)
    throw py::value_error(fmt::format("factor: must be 2 or 4, got {}", factor));
  o.method = *m;
  o.factor = factor;
  o.weights = weights;
  return o;
}

// Images of one denoiser call, checked against colour's size (ValueError naming the AOV).
struct DenoiseImages {
  FloatImage color, albedo, normal, depth, roughness, motion;
  DenoiseInput input;
};

void load_optional(py::handle object, const char* name, int channels, bool finite,
                   const FloatImage& color, FloatImage& image, const FloatImage*& slot) {
  if (object.is_none()) return;
  image = image_from_array(object, name, channels, finite);
  if (channels == 0 && image.channels != 2 && image.channels != 3)
    throw py::value_error(
        fmt::format("{}: expected 2 or 3 channels, got {}", name, image.channels));
  if (image.width != color.width || image.height != color.height)
    throw py::value_error(fmt::format("{}: size {}x{} differs from color's {}x{}", name,
                                      image.width, image.height, color.width, color.height));
  slot = &image;
}

void check_nan_policy(const std::string& policy) {
  if (policy != "zero" && policy != "raise")
    throw py::value_error(fmt::format("nan_policy: '{}' is not zero or raise", policy));
}

std::unique_ptr<DenoiseImages> denoise_images(py::handle color, py::handle albedo,
                                              py::handle normal, py::handle depth,
                                              py::handle roughness, py::handle motion,
                                              const std::string& nan_policy) {
  check_nan_policy(nan_policy);
  const bool finite = nan_policy == "raise";
  auto in = std::make_unique<DenoiseImages>();
  in->color = image_from_array(color, "color", 3, finite);
  in->input.color = &in->color;
  load_optional(albedo, "albedo", 3, finite, in->color, in->albedo, in->input.albedo);
  load_optional(normal, "normal", 3, finite, in->color, in->normal, in->input.normal);
  load_optional(depth, "depth", 1, finite, in->color, in->depth, in->input.depth);
  load_optional(roughness, "roughness", 1, finite, in->color, in->roughness, in->input.roughness);
  load_optional(motion, "motion", 0, finite, in->color, in->motion, in->input.motion);
  return in;
}

struct UpscaleImages {
  FloatImage color, depth, motion;
  UpscaleInput input;
};

std::unique_ptr<UpscaleImages> upscale_images(py::handle color, py::handle depth, py::handle motion,
                                              std::pair<float, float> jitter,
                                              const std::string& nan_policy) {
  check_nan_policy(nan_policy);
  const bool finite = nan_policy == "raise";
  auto in = std::make_unique<UpscaleImages>();
  in->color = image_from_array(color, "color", 3, finite);
  in->input.color = &in->color;
  load_optional(depth, "depth", 1, finite, in->color, in->depth, in->input.depth);
  load_optional(motion, "motion", 0, finite, in->color, in->motion, in->input.motion);
  in->input.jitter_x = jitter.first;
  in->input.jitter_y = jitter.second;
  return in;
}

py::dict pipeline_frame_dict(const PipelineFrame& f) {
  py::dict d;
  d["noisy"] = copy_image(f.noisy);
  d["denoised"] = copy_image(f.denoised);
  d["upscaled"] = copy_image(f.upscaled);
  py::array_t<uint8_t> rgb({py::ssize_t(f.height), py::ssize_t(f.width), py::ssize_t(3)});
  if (!f.rgb8.empty()) std::memcpy(rgb.mutable_data(), f.rgb8.data(), f.rgb8.size());
  d["rgb8"] = rgb;
  d["index"] = f.index;
  d["factor"] = f.factor;
  d["exposure"] = f.exposure;
  py::dict t;
  t["update"] = f.times.update;
  t["render"] = f.times.render;
  t["denoise"] = f.times.denoise;
  t["upscale"] = f.times.upscale;
  t["tonemap"] = f.times.tonemap;
  t["total"] = f.times.total;
  d["times"] = t;
  d["stats"] = stats_dict(f.stats);
  return d;
}

// light_sampling "power" | "tree", direct "nee" | "restir" | "restir-unbiased".
void set_lighting(const std::string& light_sampling, const std::string& direct, LightSampling& ls,
                  DirectLighting& d) {
  if (light_sampling == "tree")
    ls = LightSampling::tree;
  else if (light_sampling == "power")
    ls = LightSampling::power;
  else
    throw py::value_error(
        fmt::format("light_sampling: unknown '{}' (power, tree)", light_sampling));
  const auto m = direct_lighting_from_name(direct);
  if (!m)
    throw py::value_error(
        fmt::format("direct: unknown '{}' (nee, restir, restir-unbiased)", direct));
  d = *m;
}

PipelineSettings pipeline_settings(std::pair<int, int> res, int factor,
                                   std::optional<std::string> denoiser, const std::string& upscaler,
                                   int spp, int max_depth, float clamp, float exposure,
                                   double target_ms, uint64_t seed) {
  PipelineSettings s;
  s.width = res.first;
  s.height = res.second;
  s.factor = factor;
  s.denoise = denoiser.has_value() && *denoiser != "none";
  if (s.denoise) {
    auto m = denoise_method_from_name(*denoiser);
    if (!m)
      throw py::value_error(fmt::format(
          "denoiser: unknown denoiser '{}' (neural, svgf, atrous, rae, None)", *denoiser));
    s.denoiser = *m;
  }
  auto u = upscale_method_from_name(upscaler);
  if (!u)
    throw py::value_error(
        fmt::format("upscaler: unknown upsampler '{}' ({})", upscaler, upscale_method_list()));
  s.upscaler = *u;
  s.spp = spp;
  s.max_depth = max_depth;
  s.clamp = clamp;
  s.exposure = exposure;
  s.target_ms = target_ms;
  s.seed = seed;
  return s;
}

}  // namespace

void bind_render(py::module_& m) {
  py::class_<Camera>(m, "Camera",
                     "A pinhole or thin-lens camera looking from eye at target (+Y up).")
      .def(py::init([](py::handle eye, py::handle target, float vfov, float aperture,
                       float focus_distance) {
             Camera c;
             c.eye = vec3_from(eye, "eye");
             c.target = vec3_from(target, "target");
             c.vfov_degrees = vfov;
             c.aperture_radius = aperture;
             c.focus_distance = focus_distance;
             check_camera(c);
             return c;
           }),
           py::arg("eye"), py::arg("target"), py::arg("vfov") = 45.0f, py::arg("aperture") = 0.0f,
           py::arg("focus_distance") = 0.0f)
      .def_property_readonly("eye", [](const Camera& c) { return vec3_tuple(c.eye); })
      .def_property_readonly("target", [](const Camera& c) { return vec3_tuple(c.target); })
      .def_readonly("vfov", &Camera::vfov_degrees)
      .def_readonly("aperture", &Camera::aperture_radius)
      .def_readonly("focus_distance", &Camera::focus_distance)
      .def("__eq__", [](const Camera& a, const Camera& b) { return a == b; })
      .def("__repr__", [](const Camera& c) {
        return fmt::format("kestrel.Camera(eye=({}, {}, {}), target=({}, {}, {}), vfov={})",
                           c.eye.x, c.eye.y, c.eye.z, c.target.x, c.target.y, c.target.z,
                           c.vfov_degrees);
      });

  m.def(
      "view",
      [](const Scene& scene, std::optional<std::string> name) {
        // As `kestrel render`: the scene's "front" view where it has one, else "framing".
        if (!name) name = find_view(scene, "front") ? "front" : "framing";
        auto cam = find_view(scene, *name);
        if (!cam)
          throw py::value_error(
              fmt::format("view: {} has no view named '{}'", scene.source, *name));
        return *cam;
      },
      py::arg("scene"), py::arg("name") = py::none(),
      "A named view of the scene (None: 'front' where the scene has one, else 'framing', as "
      "`kestrel render`; "
      "'framing' always exists; Sponza has 'inside').");

  py::class_<CameraPath>(m, "CameraPath", "A keyframed camera path (JSON) or a turntable orbit.")
      .def_static(
          "load", [](const std::filesystem::path& path) { return CameraPath::load(path.string()); },
          py::arg("path"))
      .def_static("orbit", &CameraPath::orbit, py::arg("start"), py::arg("degrees"),
                  py::arg("seconds") = 1.0)
      .def_property_readonly("start", &CameraPath::start)
      .def_property_readonly("end", &CameraPath::end)
      .def("at", &CameraPath::at, py::arg("time"));

  py::class_<PyRenderer>(
      m, "Renderer",
      "The path tracer (NEE + MIS, every AOV) over a Scene (copied: each mesh one identity "
      "instance) or a committed InstancedScene (referenced: each render sees its last commit).")
      .def(py::init([](std::shared_ptr<Scene> scene, std::optional<std::string> environment,
                       std::optional<std::string> sun, bool sky,
                       std::optional<std::filesystem::path> lights) {
             const std::optional<Environment> env =
                 make_lighting(environment.value_or(""), sun.value_or(""), sky);
             auto r = std::make_unique<PyRenderer>();
             Scene copy = *scene;
             py::gil_scoped_release release;
             r->asset.emplace(Asset::from_scene(std::move(copy)));
             if (lights) r->asset->add_lights(load_lights(lights->string()));
             r->renderer = std::make_unique<Renderer>(r->asset->scene(), env);
             return r;
           }),
           py::arg("scene"), py::arg("environment") = py::none(), py::arg("sun") = py::none(),
           py::arg("sky") = false, py::arg("lights") = py::none(),
           "environment: None = the scene's default (a sky without emitters), 'none', 'sky', "
           "'constant:R,G,B' or an image file; sun: 'AZIMUTH,ELEVATION[,INTENSITY]' (with the "
           "physical sky unless environment is given); sky: the physical sky; lights: a lights "
           "file (point / spot / directional lights, as `kestrel render --lights`) added to the "
           "scene's.")
      .def(py::init([](std::shared_ptr<PyInstancedScene> scene,
                       std::optional<std::string> environment, std::optional<std::string> sun,
                       bool sky) {
             const std::optional<Environment> env =
                 make_lighting(environment.value_or(""), sun.value_or(""), sky);
             auto r = std::make_unique<PyRenderer>();
             r->instanced = scene;
             py::gil_scoped_release release;
             r->renderer = std::make_unique<Renderer>(scene->scene, env);
             return r;
           }),
           py::arg("scene"), py::arg("environment") = py::none(), py::arg("sun") = py::none(),
           py::arg("sky") = false)
      .def(
          "render",
          [](PyRenderer& r, const Camera& camera, int spp, py::handle res, uint64_t seed,
             int max_depth, int rr_depth, float clamp, uint32_t frame, bool jitter,
             bool fixed_jitter, double time_limit, int threads, std::optional<Camera> prev_camera,
             const std::string& light_sampling, const std::string& direct, bool radiance_cache,
             float indirect_rate) {
            RenderSettings s;
            set_lighting(light_sampling, direct, s.light_sampling, s.direct);
            s.radiance_cache = radiance_cache;
            s.indirect_rate = indirect_rate;
            std::tie(s.width, s.height) = resolution(res);
            s.spp = spp;
            s.seed = seed;
            s.max_depth = max_depth;
            s.rr_depth = rr_depth;
            s.clamp = clamp;
            s.frame = frame;
            s.jitter = jitter;
            s.fixed_jitter = fixed_jitter;
            s.time_limit_s = time_limit;
            s.threads = threads;
            if (threads < 0) throw py::value_error("threads: must be >= 0 (0 = all)");
            Frame f = without_gil(0, [&] { return r.renderer->render(camera, s, prev_camera); });
            r.last_stats = f.stats;
            r.jitter_x = f.jitter_x;
            r.jitter_y = f.jitter_y;
            return frame_dict(std::move(f));
          },
          py::arg("camera"), py::arg("spp") = 1, py::arg("res") = py::make_tuple(640, 360),
          py::arg("seed") = 0, py::arg("max_depth") = 8, py::arg("rr_depth") = 3,
          py::arg("clamp") = 0.0f, py::arg("frame") = 0, py::arg("jitter") = true,
          py::arg("fixed_jitter") = false, py::arg("time_limit") = 0.0, py::arg("threads") = 0,
          py::arg("prev_camera") = py::none(), py::arg("light_sampling") = "power",
          py::arg("direct") = "nee", py::arg("radiance_cache") = false,
          py::arg("indirect_rate") = 1.0f,
          "Renders one frame: a dict of AOVs color, albedo, normal, depth, roughness, motion, spp, "
          "variance, each a "
          "float32 (H, W, C) array (the same bits as `kestrel render` writes for the same "
          "settings). light_sampling: 'power' | 'tree'; direct: 'nee' | 'restir' (ReSTIR DI, "
          "biased) | 'restir-unbiased' (reservoirs are reused from the previous frame index); "
          "radiance_cache: paths stop at their first bounce's surface and take a world-space "
          "cache's radiance (biased; the cache is kept from the previous frame index); "
          "indirect_rate: 1, 0.5 or 0.25 of the pixels trace a first bounce per pass (stratified "
          "Russian roulette, unbiased; fewer rays, more indirect noise).")
      .def_property_readonly("last_stats",
                             [](const PyRenderer& r) { return stats_dict(r.last_stats); })
      .def_property_readonly(
          "last_jitter", [](const PyRenderer& r) { return py::make_tuple(r.jitter_x, r.jitter_y); })
      .def_property_readonly("light_count",
                             [](const PyRenderer& r) { return r.renderer->light_count(); });

  m.attr("aov_names") = [] {
    std::vector<std::string> n;
    for (int a = 0; a < aov_count; ++a) n.push_back(aov_name(Aov(a)));
    return n;
  }();

  py::class_<Denoiser>(
      m, "Denoiser",
      "A denoiser for one sequence of frames (recurrent state; reset() starts anew).")
      .def(py::init([](const std::string& method, const std::string& weights, bool recurrent,
                       bool bf16) {
             return std::make_unique<Denoiser>(denoiser_options(method, weights, recurrent, bf16));
           }),
           py::arg("method") = "neural", py::arg("weights") = "", py::arg("recurrent") = true,
           py::arg("bf16") = true)
      .def(
          "denoise",
          [](Denoiser& d, py::handle color, py::handle albedo, py::handle normal, py::handle depth,
             py::handle roughness, py::handle motion, int threads, const std::string& nan_policy,
             py::object out) {
            auto in = denoise_images(color, albedo, normal, depth, roughness, motion, nan_policy);
            FloatImage result = without_gil(threads, [&] { return d.denoise(in->input); });
            return image_out(std::move(result), out, "out");
          },
          py::arg("color"), py::arg("albedo") = py::none(), py::arg("normal") = py::none(),
          py::arg("depth") = py::none(), py::arg("roughness") = py::none(),
          py::arg("motion") = py::none(), py::arg("threads") = 0, py::arg("nan_policy") = "zero",
          py::arg("out") = py::none())
      .def("reset", &Denoiser::reset)
      .def_property_readonly(
          "method", [](const Denoiser& d) { return std::string(denoise_method_name(d.method())); })
      .def_property_readonly("parameter_count", &Denoiser::parameter_count)
      .def_property_readonly("uses_bf16", &Denoiser::uses_bf16);

  m.def(
      "denoise",
      [](py::handle color, py::handle albedo, py::handle normal, py::handle depth,
         py::handle roughness, py::handle motion, const std::string& method,
         const std::string& weights, int threads, const std::string& nan_policy, py::object out) {
        auto in = denoise_images(color, albedo, normal, depth, roughness, motion, nan_policy);
        const DenoiserOptions options = denoiser_options(method, weights, true);
        FloatImage result = without_gil(threads, [&] {
          Denoiser d(options);
          return d.denoise(in->input);
        });
        return image_out(std::move(result), out, "out");
      },
      py::arg("color"), py::arg("albedo") = py::none(), py::arg("normal") = py::none(),
      py::arg("depth") = py::none(), py::arg("roughness") = py::none(),
      py::arg("motion") = py::none(), py::arg("method") = "neural", py::arg("weights") = "",
      py::arg("threads") = 0, py::arg("nan_policy") = "zero", py::arg("out") = py::none(),
      "Denoises one frame: color (H, W, 3) float32 linear HDR; optional albedo, normal (H, W, 3), "
      "depth, roughness "
      "(H, W) or (H, W, 1), motion (H, W, 2|3). Returns (H, W, 3) float32 (or writes out=).");

  py::class_<Upscaler>(
      m, "Upscaler",
      "A temporal upsampler for one sequence (history carried; reset() starts anew).")
      .def(py::init(
               [](const std::string& method, int factor, const std::string& weights, bool bf16) {
                 return std::make_unique<Upscaler>(upscaler_options(method, factor, weights, bf16));
               }),
           py::arg("method") = "neural", py::arg("factor") = 2, py::arg("weights") = "",
           py::arg("bf16") = true)
      .def(
          "upscale",
          [](Upscaler& u, py::handle color, py::handle depth, py::handle motion,
             std::pair<float, float> jitter, int threads, const std::string& nan_policy,
             py::object out) {
            auto in = upscale_images(color, depth, motion, jitter, nan_policy);
            FloatImage result = without_gil(threads, [&] { return u.upscale(in->input); });
            return image_out(std::move(result), out, "out");
          },
          py::arg("color"), py::arg("depth") = py::none(), py::arg("motion") = py::none(),
          py::arg("jitter") = std::pair<float, float>(0.5f, 0.5f), py::arg("threads") = 0,
          py::arg("nan_policy") = "zero", py::arg("out") = py::none())
      .def("reset", &Upscaler::reset)
      .def_property_readonly(
          "method", [](const Upscaler& u) { return std::string(upscale_method_name(u.method())); })
      .def_property_readonly("factor", &Upscaler::factor)
      .def_property_readonly("parameter_count", &Upscaler::parameter_count)
      .def_property_readonly("uses_bf16", &Upscaler::uses_bf16);

  m.def(
      "upscale",
      [](py::handle color, py::handle depth, py::handle motion, int factor,
         const std::string& method, std::pair<float, float> jitter, const std::string& weights,
         int threads, const std::string& nan_policy, py::object out) {
        auto in = upscale_images(color, depth, motion, jitter, nan_policy);
        const UpscalerOptions options = upscaler_options(method, factor, weights);
        FloatImage result = without_gil(threads, [&] {
          Upscaler u(options);
          return u.upscale(in->input);
        });
        return image_out(std::move(result), out, "out");
      },
      py::arg("color"), py::arg("depth") = py::none(), py::arg("motion") = py::none(),
      py::arg("factor") = 2, py::arg("method") = "bicubic",
      py::arg("jitter") = std::pair<float, float>(0.5f, 0.5f), py::arg("weights") = "",
      py::arg("threads") = 0, py::arg("nan_policy") = "zero", py::arg("out") = py::none(),
      "Upsamples one point-sampled frame (H, W, 3) by factor 2 or 4. For sequences (temporal "
      "methods), use Upscaler.");

  py::class_<Pipeline>(m, "Pipeline",
                       "The real-time loop: update, 1-spp render, denoise, upsample, tone map.")
      .def(py::init([](const std::filesystem::path& scene, py::handle res, int factor,
                       std::optional<std::string> denoiser, const std::string& upscaler, int spp,
                       int max_depth, float clamp, float exposure, double target_ms, uint64_t seed,
                       const std::string& environment, const std::string& sun, bool sky,
                       bool auto_exposure, const std::string& light_sampling,
                       const std::string& direct, bool radiance_cache, float indirect_rate,
                       std::optional<std::filesystem::path> lights) {
             PipelineSettings s =
                 pipeline_settings(resolution(res), factor, denoiser, upscaler, spp, max_depth,
                                   clamp, exposure, target_ms, seed);
             s.auto_lighting = direct == "auto";
             set_lighting(light_sampling, s.auto_lighting ? "nee" : direct, s.light_sampling,
                          s.direct);
             s.sun = sun, s.sky = sky, s.auto_exposure = auto_exposure;
             s.radiance_cache = radiance_cache;
             s.indirect_rate = indirect_rate;
             py::gil_scoped_release release;
             if (!lights) return std::make_unique<Pipeline>(scene.string(), s, environment);
             Asset asset = Asset::load(scene.string());
             asset.add_lights(load_lights(lights->string()));
             return std::make_unique<Pipeline>(std::move(asset), s, environment);
           }),
           py::arg("scene"), py::arg("res") = py::make_tuple(1280, 720), py::arg("factor") = 2,
           py::arg("denoiser") = "neural", py::arg("upscaler") = "neural", py::arg("spp") = 1,
           py::arg("max_depth") = 4, py::arg("clamp") = 16.0f, py::arg("exposure") = 0.0f,
           py::arg("target_ms") = 0.0, py::arg("seed") = 0, py::arg("environment") = "",
           py::arg("sun") = "", py::arg("sky") = false, py::arg("auto_exposure") = false,
           py::arg("light_sampling") = "power", py::arg("direct") = "auto",
           py::arg("radiance_cache") = true, py::arg("indirect_rate") = 0.5f,
           py::arg("lights") = py::none(),
           "radiance_cache: paths stop at their first bounce's surface and take a world-space "
           "cache's radiance there (biased; as `kestrel run`); "
           "direct: 'auto' (ReSTIR over the light tree for >= 64 lights, else light_sampling "
           "and NEE) | 'nee' | 'restir' | 'restir-unbiased'; "
           "sun: 'AZIMUTH,ELEVATION[,INTENSITY]' (degrees; with the physical sky unless "
           "environment is "
           "given); sky: the physical sky; auto_exposure: the tone map follows the image; "
           "indirect_rate: 1, 0.5 or 0.25 of the pixels trace a first bounce each frame "
           "(0.5, a checkerboard, as `kestrel run`: the loop's frame budget; target_ms lowers "
           "it before it coarsens the factor); lights: a lights file added to the scene's.")
      .def(
          "frame",
          [](Pipeline& p, const Camera& camera, double time) {
            if (!std::isfinite(time)) throw py::value_error("time: must be finite");
            const PipelineFrame& f =
                without_gil(0, [&]() -> const PipelineFrame& { return p.frame(camera, time); });
            return pipeline_frame_dict(f);
          },
          py::arg("camera"), py::arg("time") = 0.0,
          "One frame: a dict of noisy, denoised, upscaled (float32 (H, W, 3)), rgb8 (uint8 (H, W, "
          "3)), times (ms per "
          "stage), stats, index, factor. The arrays are copies (the loop reuses its images).")
      .def(
          "accumulate",
          [](Pipeline& p, const Camera& camera, double time) {
            const PipelineFrame& f = without_gil(
                0, [&]() -> const PipelineFrame& { return p.accumulate(camera, time); });
            return pipeline_frame_dict(f);
          },
          py::arg("camera"), py::arg("time") = 0.0,
          "Adds one sample per pixel to the progressive reference.")
      .def_property_readonly("accumulated", &Pipeline::accumulated)
      .def("reset", &Pipeline::reset)
      .def_property_readonly("source", &Pipeline::source)
      .def_property_readonly("animation_duration", &Pipeline::animation_duration)
      .def_property_readonly("triangle_count", &Pipeline::triangle_count);
}

}  // namespace kestrel::python
