// kestrel public API: the path tracer. Cameras (pinhole, thin lens, named views, keyframed
// paths), environments, render settings, the frame with every auxiliary buffer (AOV)
// reconstruction needs, and the Renderer over an InstancedScene (kestrel/asset.h loads one).
// Conventions (docs/renderer.md): images rows top to bottom; +Y up; world-space normals;
// depth along the camera's forward axis; motion vectors in pixels pointing from a pixel of
// this frame to where the same surface point was in the previous frame.
#pragma once
#include <array>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "kestrel/asset.h"
#include "kestrel/instances.h"
#include "kestrel/io.h"
#include "kestrel/scene.h"

namespace kestrel {

/// A camera looking from eye at target (+Y up). aperture_radius > 0 makes it a thin lens
/// focused at focus_distance (0 = the eye-target distance).
struct Camera {
  Vec3 eye{0, 0, 0}, target{0, 0, -1};
  float vfov_degrees = 45.0f;
  float aperture_radius = 0.0f;
  float focus_distance = 0.0f;
  bool operator==(const Camera&) const = default;
};

/// Throws Error unless the camera can make rays: finite values, eye != target, vfov in
/// (0, 180), aperture and focus distance >= 0.
void check_camera(const Camera& camera);

/// The framing view of a scene: target the centre of its bounds, eye = target +
/// normalize(0.3, 0.35, -1) * r / sin(vfov / 2), r = half the diagonal, vfov 45.
Camera framing_camera(const Scene& scene);
/// The same for a box (empty: looking at the origin from distance r = 1).
Camera framing_camera(const Bounds3& bounds);

/// Named views: a JSON object {"views": {"NAME": {"eye": [x,y,z], "target": [x,y,z],
/// "vfov": deg, "aperture": r, "focus_distance": d}}}. Errors name the file and the view.
std::map<std::string, Camera> load_views(const std::string& path);
/// Where the views of a scene file are looked for, in order: "<scene without extension>
/// .views.json" beside it, then kestrel's data/views/<stem>.views.json.
std::vector<std::string> view_files_for(const std::string& scene_path);
/// A named view of the scene ("framing" always exists, computed from the scene); nullopt
/// when no views file names it.
std::optional<Camera> find_view(const Scene& scene, const std::string& name);
/// The same for a loaded asset (its source's views files, its bounds for "framing").
std::optional<Camera> find_view(const Asset& asset, const std::string& name);

/// The lighting a scene's views file suggests, `"lighting": {"env": SPEC, "sun":
/// "AZ,EL[,I]", "sky": true}` (each optional; as make_lighting's arguments). `kestrel run` and
/// `view` use it when no --env, --sun or --sky is given (Sponza: a sun through its opening).
struct SceneLighting {
  std::string env, sun;
  bool sky = false;
};
/// The first views file of scene_path (view_files_for) with a "lighting" entry; nullopt when
/// none has one. Throws Error naming the file for a malformed entry.
std::optional<SceneLighting> suggested_lighting(const std::string& scene_path);

/// A keyframed camera path: {"keyframes": [{"time": s, "eye": [...], "target": [...],
/// "vfov": deg}, ...]} with increasing times; eye and target follow a centripetal
/// Catmull-Rom spline through the keys, vfov / aperture / focus are interpolated linearly.
struct CameraPath {
  struct Key {
    double time = 0;
    Camera camera;
  };
  std::vector<Key> keys;
  static CameraPath load(const std::string& path);
  /// A turntable: `start`'s eye turned about the vertical (+Y) axis through its target by
  /// `degrees` over `seconds` (keys every 15 degrees at most). Throws Error on a bad camera
  /// or non-finite / non-positive arguments.
  static CameraPath orbit(const Camera& start, double degrees, double seconds = 1.0);
  double start() const { return keys.empty() ? 0.0 : keys.front().time; }
  double end() const { return keys.empty() ? 0.0 : keys.back().time; }
  Camera at(double time) const;
};

/// The sun: a disk of angular radius `angular_radius_degrees` around `direction` (unit,
/// towards the sun) giving `irradiance` (per channel) to a surface facing it. Sampled as an
/// area light (soft shadows from its size) and seen by rays that escape towards it.
struct Sun {
  Vec3 direction{0.5f, 0.70710677f, -0.5f};  ///< azimuth 135, elevation 45
  Vec3 irradiance{10, 10, 10};
  float angular_radius_degrees = 0.267f;  ///< the real sun's
  /// "AZIMUTH,ELEVATION[,INTENSITY]" in degrees: azimuth from north (-Z) towards east (+X),
  /// elevation above the horizon (+Y up, -90..90); INTENSITY the irradiance (white, default
  /// 10). Throws Error naming the spec.
  static Sun parse(const std::string& spec);
  /// Throws Error(invalid_argument) unless every value is finite, the direction non-zero,
  /// the irradiance >= 0 and the radius in (0, 45] degrees.
  void check() const;
};

/// Light from infinitely far away: a constant radiance or an equirectangular image
/// (u = 0.5 + atan2(d.x, -d.z) / 2pi, v = acos(d.y) / pi, row 0 = straight up), scaled.
struct Environment {
  Vec3 color{0, 0, 0};
  /// CIE overcast sky: radiance color * (1 + 2 cos theta) / 3 above the horizon (theta from
  /// +Y), color * 0.1 below (a dark ground). Used when image is empty.
  bool overcast = false;
  FloatImage image;  ///< 3 channels, linear; empty = constant colour
  float scale = 1.0f;
  /// Light samples of the image drawn cosine-weighted about the surface normal (as for the
  /// constant and overcast environments) instead of by the image's luminance: for smooth
  /// skies, where it costs no table search and no sample falls below the surface.
  /// physical_sky sets it; an image file leaves it false.
  bool cosine_sampled = false;
  /// The sun, beside whatever else the environment is (nullopt: none).
  std::optional<Sun> sun;
  /// A clear sky for the sun's direction (Preetham, Shirley & Smits 1999, `turbidity` in
  /// [1.7, 10]: the Perez distribution of luminance and chromaticity), baked into a 512 x 256
  /// equirectangular image, its light samples cosine-weighted; the ground below the horizon 0.1 x
  /// the horizon's luminance. Scaled so a 45-degree sun's zenith is 1 (the sky dims as the
  /// sun sets). The sun itself is set as `sun`.
  static Environment physical_sky(const Sun& sun, float turbidity = 3.0f);
  /// "none", "constant:R,G,B" (or "R,G,B"), "sky" (a white CIE overcast sky: zenith 1,
  /// horizon 1/3, ground 0.1; the default for scenes without emitters), or an image file
  /// (.hdr, .exr, .pfm, .png): see read_float_image.
  static Environment parse(const std::string& spec);
};

/// A lights file: {"lights": [{"name": "...", "type": "point" | "spot" | "directional",
/// "position": [x, y, z], "direction": [x, y, z], "color": [r, g, b], "intensity": I,
/// "range": r, "inner_cone": rad, "outer_cone": rad}, ...]} (fields as Light; omitted ones
/// keep Light's defaults; directions are normalised). Errors name the file and the light.
std::vector<Light> load_lights(const std::string& path);

/// The lighting the CLI flags ask for: `env` (Environment::parse; "" = the scene's default),
/// `sun` ("" = none, else Sun::parse) and `sky` (the physical sky). A sun without --env gets
/// the physical sky; --sky without a sun uses the default Sun. nullopt = the scene's default
/// (neither given). Throws Error for bad specs or --sky with --env.
std::optional<Environment> make_lighting(const std::string& env, const std::string& sun, bool sky);

/// How next-event estimation picks one of the local lights (emissive triangles, point and
/// spot lights). Both are unbiased.
enum class LightSampling {
  power,  ///< in proportion to power (the default)
  tree,   ///< by a light tree's estimate of each light's contribution at the point (many
          ///< lights; scenes with directional lights fall back to power)
};

/// How the direct light at the first surface a camera ray hits is estimated.
enum class DirectLighting {
  nee,              ///< one light sample, MIS with the BSDF (the default; unbiased)
  restir,           ///< ReSTIR DI (Bitterli et al. 2020): resampled candidates, visibility reuse,
                    ///< temporal reuse (balance heuristic), spatial reuse (1/M weights). Biased
                    ///< (darkens where visibility differs across reused pixels).
  restir_unbiased,  ///< the same reuse without visibility reuse and with Alg. 6's spatial
                    ///< normalisation (only reservoirs that could have produced the sample
                    ///< count): unbiased, noisier under occlusion
};
/// "nee", "restir", "restir-unbiased"; nullopt for anything else.
std::optional<DirectLighting> direct_lighting_from_name(const std::string& name);

/// What a render does. The same settings and seed give the same bits for any thread count.
struct RenderSettings {
  int width = 640, height = 360;
  int spp = 1;              ///< samples per pixel (a time limit may stop earlier)
  double time_limit_s = 0;  ///< > 0: stop after the pass during which this much time passed
  uint64_t seed = 0;
  uint32_t frame = 0;  ///< frame index: picks the Halton jitter and decorrelates noise
  bool jitter = true;  ///< sub-pixel jitter (Halton 2,3 by frame); false = pixel centres
  /// Every pass at the frame's jitter (Halton index frame + 1, the 1-spp sequence): a clean,
  /// point-sampled low-resolution frame, as temporal upsamplers see it, from many passes.
  bool fixed_jitter = false;
  int max_depth = 8;  ///< path vertices after the camera (1 = direct light only)
  int rr_depth = 3;   ///< Russian roulette from this bounce on
  float clamp = 0;    ///< > 0: clamp each sample's radiance (biased); 0 = off
  /// The share of pixels whose path goes on after the first hit: 1 (all), 0.5 or 0.25. The
  /// others stop there (their direct light is kept) and the survivors' paths count 1 / rate
  /// times: Russian roulette at the first bounce, unbiased, stratified over the image (a
  /// checkerboard, or one pixel of each 2x2 block, moving with the frame index) so that every
  /// pixel goes on once in 1 / rate frames. Fewer bounce rays for more indirect noise.
  float indirect_rate = 1.0f;
  LightSampling light_sampling = LightSampling::power;
  /// ReSTIR keeps reservoirs between renders of one Renderer: frame f's first pass reuses
  /// the last pass of frame f - 1 (any other frame index starts afresh), later passes reuse
  /// the pass before. Glossy-to-mirror surfaces (roughness < 0.2) keep NEE with MIS.
  DirectLighting direct = DirectLighting::nee;
  int restir_candidates = 8;  ///< light samples resampled per pixel (ReSTIR's M), 1..64
  int restir_neighbors = 3;   ///< spatial reuse: neighbours within 16 px of the same tile, 0..16
  /// A world-space radiance cache (biased; docs/renderer.md "Radiance cache"): paths stop at
  /// the surface their first bounce from a rough surface reaches and take its cell's mean
  /// outgoing radiance, learnt from the paths (1 in 16, and every one whose cell is not yet
  /// known) that go on. Kept between renders of one Renderer like ReSTIR's history (frame f
  /// reuses frame f - 1's cache; any other frame index starts afresh).
  bool radiance_cache = false;
  int threads = 0;        ///< 0 = all the library may use
  bool progress = false;  ///< a progress bar on stderr
};

/// Edge of the square tiles a render is split into, pixels; tiles are numbered row-major.
int render_tile_size();
/// Tiles of a width x height image.
size_t render_tile_count(int width, int height);

/// The Halton (2, 3) sub-pixel position of sample `index` (pass 0 of frame `index` at 1 spp,
/// every pass of it with fixed_jitter): radical inverses of index + 1, in [0, 1).
void frame_jitter(uint32_t index, float& jx, float& jy);

/// The auxiliary buffers, in file order. Every frame has all of them.
enum class Aov { color, albedo, normal, depth, roughness, motion, spp, variance };
inline constexpr int aov_count = 8;
/// "color", "albedo", "normal", "depth", "roughness", "motion", "spp", "variance".
const char* aov_name(Aov aov);
/// Channels of an AOV's image (3, 3, 3, 1, 1, 2, 1, 1).
int aov_channels(Aov aov);

struct RenderStats {
  double ms = 0;               ///< wall time of the render
  double trace_ms = 0;         ///< time inside trace/occluded calls (wall time x threads)
  double total_thread_ms = 0;  ///< time inside the render's passes (wall time x threads)
  uint64_t camera_rays = 0, bounce_rays = 0, shadow_rays = 0;
  /// Where the wall time went, by step of the wavefront (ms; summed over passes): camera rays
  /// made; traced; the first hits shaded (surface, texels, AOVs, light and BSDF samples);
  /// their shadow rays (and ReSTIR's reuse) traced and applied; the later bounces traced,
  /// shaded, their shadow rays traced; the samples added to the film. Steps that trace
  /// include gathering the tiles' rays into one batch. A distributed render sums each step
  /// over its ranks (as it sums trace_ms).
  struct Steps {
    double camera = 0, trace_camera = 0, shade_first = 0, shadows_first = 0;
    double trace_bounces = 0, shade_bounces = 0, shadows_bounces = 0, film = 0;
    /// Every step's name and member, in order (for sums, printing and sending).
    static constexpr std::array<std::pair<const char*, double Steps::*>, 8> fields() {
      return {{{"camera", &Steps::camera},
               {"trace_camera", &Steps::trace_camera},
               {"shade_first", &Steps::shade_first},
               {"shadows_first", &Steps::shadows_first},
               {"trace_bounces", &Steps::trace_bounces},
               {"shade_bounces", &Steps::shade_bounces},
               {"shadows_bounces", &Steps::shadows_bounces},
               {"film", &Steps::film}}};
    }
    Steps& operator+=(const Steps& o) {
      for (const auto& [name, m] : fields()) this->*m += o.*m;
      return *this;
    }
  } steps;
  int passes = 0;  ///< samples per pixel done
  uint64_t rays() const { return camera_rays + bounce_rays + shadow_rays; }
};

/// One rendered frame: every AOV as a float image (docs/renderer.md):
/// - color: linear HDR radiance, mean of the samples;
/// - albedo: reflectance of the first non-specular surface (its base colour; the
///   environment's radiance for camera rays that escape, as Open Image Denoise expects);
/// - normal: world-space shading normal at that surface, facing the camera (0 on a miss);
/// - depth: distance along the camera's forward axis to the first hit (0 on a miss);
/// - roughness: perceptual roughness of the first non-specular surface (0 on a miss);
/// - motion: (dx, dy) in pixels such that the surface seen at pixel p was at p + motion in
///   the previous frame (previous camera and instance transforms; 0 on a miss... and for
///   samples whose point was behind the previous camera);
/// - spp: samples per pixel; variance: the variance of the colour's luminance mean
///   (sample variance / spp; 0 at 1 spp).
/// Each AOV is the mean over the pixel's samples.
struct Frame {
  int width = 0, height = 0;
  FloatImage aov[aov_count];
  float jitter_x = 0.5f, jitter_y = 0.5f;  ///< sub-pixel position of pass 0's samples
  RenderStats stats;
  FloatImage& operator[](Aov a) { return aov[int(a)]; }
  const FloatImage& operator[](Aov a) const { return aov[int(a)]; }
  /// Every AOV as EXR layers (color as bare R, G, B; "albedo.R", "normal.X", "depth.Z", ...).
  std::vector<ImageLayer> layers() const;
};

/// Writes the frame: a multi-layer EXR with every AOV.
void write_frame_exr(const std::string& path, const Frame& frame);
/// Writes one PFM per AOV into dir (color.pfm, albedo.pfm, normal.pfm, depth.pfm,
/// roughness.pfm, motion.pfm (3 channels, the third 0), spp.pfm, variance.pfm).
void write_frame_pfms(const std::string& dir, const Frame& frame);
/// The documented tone map: exposure 2^stops, ACES filmic (Narkowicz 2015), sRGB OETF.
std::vector<uint8_t> tonemap_srgb8(const FloatImage& color, float exposure_stops = 0.0f);
/// The same into `out` (resized; its storage reused).
void tonemap_srgb8(const FloatImage& color, float exposure_stops, std::vector<uint8_t>& out);
/// One channel's tone map as above (for evaluation code).
float tonemap_aces_srgb(float linear);

/// The path tracer: unidirectional, next-event estimation with multiple importance sampling
/// (power heuristic), Russian roulette, on the metallic-roughness material model (Lambertian
/// diffuse base, dielectric GGX coat, GGX conductor; Heitz 2018 visible-normal sampling).
/// Emissive triangles are area lights (two-sided) sampled by power.
class Renderer {
 public:
  /// Renders a committed scene, referenced (it must outlive the renderer). Each render sees
  /// the scene as of its last commit(); the transforms of the commit before drive the motion
  /// vectors. `environment`: nullopt = "sky" when the scene has no emissive triangle, else
  /// none. Throws Error naming the scene's source for bad materials or no valid triangle.
  explicit Renderer(const InstancedScene& scene,
                    std::optional<Environment> environment = std::nullopt);
  ~Renderer();
  Renderer(Renderer&&) noexcept;
  Renderer& operator=(Renderer&&) noexcept;
  /// Renders one frame. prev_camera: the previous frame's camera (for motion vectors;
  /// nullopt = this camera). Throws Error for bad settings or a bad camera.
  Frame render(const Camera& camera, const RenderSettings& settings,
               std::optional<Camera> prev_camera = std::nullopt);
  /// The same into `frame`, reusing its images' storage (a loop that keeps its Frame pays
  /// no allocation, page faults included, frame after frame).
  void render(const Camera& camera, const RenderSettings& settings,
              std::optional<Camera> prev_camera, Frame& frame);
  /// Renders only the listed tiles (render_tile_size() pixels square, row-major over the
  /// image; every pass of each) into `frame`, which is sized (and zeroed) when its size
  /// differs from the settings'; other pixels are left as they are. Every rendered pixel
  /// equals render()'s bit for bit, so tiles can be spread over processes (distributed
  /// rendering). frame.stats adds this call's rays and times. No time limit.
  void render_tiles(const Camera& camera, const RenderSettings& settings,
                    std::span<const uint32_t> tiles, Frame& frame,
                    std::optional<Camera> prev_camera = std::nullopt);
  /// Bounds of the scene as rendered.
  Bounds3 bounds() const;
  size_t light_count() const;
  const Environment& environment() const;

 private:
  friend struct RendererTesting;  // benchmark hooks (src/render/testing.h)
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace kestrel
