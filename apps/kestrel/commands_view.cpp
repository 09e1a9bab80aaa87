// `kestrel view`: the real-time pipeline in an SDL2 window. WASD (+ Q/E down/up, Shift
// faster) moves, dragging with the left mouse button looks around; 1 noisy, 2 denoised,
// 3 upsampled (the default), 4 progressive reference (accumulates while the camera rests);
// Tab the overlay, F12 a screenshot, Esc quits; drop a scene file on the window to load it.
#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <vector>

#include "commands.h"
#include "kestrel/error.h"
#include "kestrel/io.h"
#include "kestrel/pipeline.h"
#include "pipeline_args.h"

#ifdef KESTREL_HAVE_SDL2
#include <SDL.h>
#ifdef KESTREL_HAVE_SDL2_TTF
#include <SDL_ttf.h>
#endif
#endif

namespace kestrel::cli {

namespace {

struct ViewArgs {
  PipelineArgs p;
  std::string view, path, screenshot, font = "/usr/share/fonts/truetype/dejavu/DejaVuSansMono.ttf";
  int frames = 0;  // 0 = until closed
  int stage = 3;
  bool no_overlay = false;
};

#ifdef KESTREL_HAVE_SDL2

// A camera as eye + yaw/pitch (radians; yaw 0 looks down -Z), for mouse look.
struct FlyCamera {
  Vec3 eye{0, 0, 0};
  float yaw = 0, pitch = 0, vfov = 45, aperture = 0, focus = 0;
  static FlyCamera from(const Camera& c) {
    FlyCamera f;
    f.eye = c.eye;
    const Vec3 d = c.target - c.eye;
    const float len = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
    f.yaw = std::atan2(d.x, -d.z);
    f.pitch = std::asin(std::clamp(d.y / len, -1.0f, 1.0f));
    f.vfov = c.vfov_degrees, f.aperture = c.aperture_radius, f.focus = c.focus_distance;
    return f;
  }
  Vec3 forward() const {
    return {std::sin(yaw) * std::cos(pitch), std::sin(pitch), -std::cos(yaw) * std::cos(pitch)};
  }
  Vec3 right() const { return {std::cos(yaw), 0, std::sin(yaw)}; }
  Camera camera() const {
    Camera c;
    c.eye = eye, c.target = eye + forward(), c.vfov_degrees = vfov, c.aperture_radius = aperture,
    c.focus_distance = focus;
    return c;
  }
};

const char* stage_name(int s) {
  switch (s) {
    case 1:
      return "noisy";
    case 2:
      return "denoised";
    case 4:
      return "reference";
    default:
      return "upsampled";
  }
}

// The displayed stage as RGB8 at the window's size: the frame's own for the output stages,
// else `scratch`, the internal-resolution stage nearest-upsampled.
const std::vector<uint8_t>& stage_pixels(const PipelineFrame& f, int stage, float exposure,
                                         std::vector<uint8_t>& scratch) {
  if (stage == 3 || stage == 4 || f.factor == 1) return f.rgb8;
  std::vector<uint8_t>& rgb = scratch;
  const FloatImage& src = stage == 1 ? f.noisy : f.denoised;
  const std::vector<uint8_t> small = tonemap_srgb8(src, exposure);
  rgb.resize(size_t(f.width) * size_t(f.height) * 3);
  for (int y = 0; y < f.height; ++y)
    for (int x = 0; x < f.width; ++x) {
      const size_t s = (size_t(y / f.factor) * size_t(src.width) + size_t(x / f.factor)) * 3;
      const size_t d = (size_t(y) * size_t(f.width) + size_t(x)) * 3;
      rgb[d] = small[s], rgb[d + 1] = small[s + 1], rgb[d + 2] = small[s + 2];
    }
  return rgb;
}

void view(ViewArgs& a) {
  PipelineSettings settings = a.p.settings();
  std::string scene_path = a.p.scene;
  std::unique_ptr<Pipeline> pipeline = a.p.pipeline(settings);
  std::optional<CameraPath> path;
  if (!a.path.empty()) path = camera_path_for(pipeline->asset(), a.path, a.view);
  FlyCamera fly =
      FlyCamera::from(path ? path->at(path->start()) : start_camera_for(pipeline->asset(), a.view));
  auto speed_of = [](const Pipeline& p) {
    const Bounds3 b = p.bounds();
    const Vec3 d = b.hi - b.lo;
    return 0.25f * std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
  };
  float speed = speed_of(*pipeline);

  if (SDL_Init(SDL_INIT_VIDEO) != 0)
    throw Error(ErrorCode::io_error, fmt::format("view: SDL_Init failed: {}", SDL_GetError()));
  struct Quit {
    ~Quit() { SDL_Quit(); }
  } quit_sdl;
  SDL_Window* window = SDL_CreateWindow("kestrel", SDL_WINDOWPOS_CENTERED, SDL_WINDOWPOS_CENTERED,
                                        settings.width, settings.height, 0);
  if (!window)
    throw Error(ErrorCode::io_error, fmt::format("view: cannot open a window: {}", SDL_GetError()));
  SDL_Renderer* ren = SDL_CreateRenderer(window, -1, 0);
  if (!ren) ren = SDL_CreateRenderer(window, -1, SDL_RENDERER_SOFTWARE);
  if (!ren)
    throw Error(ErrorCode::io_error, fmt::format("view: no SDL renderer: {}", SDL_GetError()));
  SDL_Texture* tex = SDL_CreateTexture(ren, SDL_PIXELFORMAT_RGB24, SDL_TEXTUREACCESS_STREAMING,
                                       settings.width, settings.height);
  SDL_EventState(SDL_DROPFILE, SDL_ENABLE);
#ifdef KESTREL_HAVE_SDL2_TTF
  TTF_Font* font = nullptr;
  if (TTF_Init() == 0) font = TTF_OpenFont(a.font.c_str(), 14);
  if (!font) fmt::print(stderr, "view: no overlay font ({}); stats go to the title bar\n", a.font);
#endif
  bool running = true, overlay = !a.no_overlay, dragging = false;
  int stage = std::clamp(a.stage, 1, 4);
  std::vector<uint8_t> scratch;
  const std::vector<uint8_t>* shown = nullptr;  // the last frame's pixels (F12)
  std::string message;
  double fps = 0;
  int frame_count = 0;
  auto last = std::chrono::steady_clock::now();
  Camera prev_camera = fly.camera();
  double time = 0;
  while (running) {
    const auto now = std::chrono::steady_clock::now();
    const float dt = std::min(std::chrono::duration<float>(now - last).count(), 0.25f);
    last = now;
    SDL_Event e;
    while (SDL_PollEvent(&e)) {
      if (e.type == SDL_QUIT)
        running = false;
      else if (e.type == SDL_KEYDOWN) {
        switch (e.key.keysym.sym) {
          case SDLK_ESCAPE:
            running = false;
            break;
          case SDLK_1:
            stage = 1;
            break;
          case SDLK_2:
            stage = 2;
            break;
          case SDLK_3:
            stage = 3;
            break;
          case SDLK_4:
            stage = 4;
            break;
          case SDLK_TAB:
            overlay = !overlay;
            break;
          case SDLK_F12: {
            const std::string shot = fmt::format("kestrel_{:04d}.png", frame_count);
            if (shown) write_png(shot, settings.width, settings.height, *shown);
            message = "saved " + shot;
            break;
          }
          default:
            break;
        }
      } else if (e.type == SDL_MOUSEBUTTONDOWN && e.button.button == SDL_BUTTON_LEFT)
        dragging = true;
      else if (e.type == SDL_MOUSEBUTTONUP && e.button.button == SDL_BUTTON_LEFT)
        dragging = false;
      else if (e.type == SDL_MOUSEMOTION && dragging) {
        fly.yaw += 0.004f * float(e.motion.xrel);
        fly.pitch = std::clamp(fly.pitch - 0.004f * float(e.motion.yrel), -1.5f, 1.5f);
      } else if (e.type == SDL_DROPFILE) {
        const std::string file = e.drop.file;
        SDL_free(e.drop.file);
        try {
          auto next = std::make_unique<Pipeline>(file, settings, a.p.env);
          pipeline = std::move(next);
          scene_path = file, path.reset();
          fly = FlyCamera::from(start_camera_for(pipeline->asset(), ""));
          speed = speed_of(*pipeline);
          message = "loaded " + file;
        } catch (const Error& err) {
          message = err.what();
          fmt::print(stderr, "view: {}\n", err.what());
        }
      }
    }
    const Uint8* keys = SDL_GetKeyboardState(nullptr);
    const float step = speed * dt * (keys[SDL_SCANCODE_LSHIFT] ? 4.0f : 1.0f);
    const Vec3 fw = fly.forward(), rt = fly.right();
    if (keys[SDL_SCANCODE_W]) fly.eye = fly.eye + fw * step;
    if (keys[SDL_SCANCODE_S]) fly.eye = fly.eye + fw * -step;
    if (keys[SDL_SCANCODE_D]) fly.eye = fly.eye + rt * step;
    if (keys[SDL_SCANCODE_A]) fly.eye = fly.eye + rt * -step;
    if (keys[SDL_SCANCODE_E]) fly.eye.y += step;
    if (keys[SDL_SCANCODE_Q]) fly.eye.y -= step;
    Camera camera = fly.camera();
    if (path) {  // scripted: the path's frames spread over --frames, as `kestrel run`
      const int n = std::max(a.frames, 1);
      time = n > 1 ? path->start() + (path->end() - path->start()) *
                                         double(std::min(frame_count, n - 1)) / double(n - 1)
                   : path->start();
      camera = path->at(time);
    } else if (pipeline->animation_duration() > 0) {
      time += dt;
    }
    const bool resting = camera == prev_camera && pipeline->animation_duration() == 0;
    prev_camera = camera;
    const PipelineFrame& f =
        stage == 4 && resting ? pipeline->accumulate(camera, time) : pipeline->frame(camera, time);
    shown = &stage_pixels(f, stage == 4 && !resting ? 3 : stage, settings.exposure, scratch);
    SDL_UpdateTexture(tex, nullptr, shown->data(), settings.width * 3);
    SDL_RenderClear(ren);
    SDL_RenderCopy(ren, tex, nullptr, nullptr);
    fps = fps == 0 ? 1000.0 / f.times.total : 0.9 * fps + 0.1 * 1000.0 / f.times.total;
    const std::string stats = fmt::format(
        "{} x{} {}x{}->{}x{}  {:.1f} fps  render {:.1f} denoise {:.1f} upscale {:.1f} tonemap "
        "{:.1f} ms  {:.1f} Mrays/s{}",
        stage == 4 && resting ? fmt::format("reference {} spp", pipeline->accumulated())
                              : stage_name(stage),
        f.factor, f.internal_width, f.internal_height, f.width, f.height, fps, f.times.render,
        f.times.denoise, f.times.upscale, f.times.tonemap,
        double(f.stats.rays()) / (f.times.render * 1e3), message.empty() ? "" : "  " + message);
    bool drawn = false;
#ifdef KESTREL_HAVE_SDL2_TTF
    if (overlay && font) {
      SDL_Surface* text =
          TTF_RenderUTF8_Blended_Wrapped(font, stats.c_str(), SDL_Color{255, 255, 255, 255},
                                         Uint32(std::max(200, settings.width - 16)));
      if (text) {
        SDL_Texture* t = SDL_CreateTextureFromSurface(ren, text);
        SDL_Rect box{4, 4, text->w + 8, text->h + 4}, dst{8, 6, text->w, text->h};
        SDL_SetRenderDrawBlendMode(ren, SDL_BLENDMODE_BLEND);
        SDL_SetRenderDrawColor(ren, 0, 0, 0, 160);
        SDL_RenderFillRect(ren, &box);
        SDL_RenderCopy(ren, t, nullptr, &dst);
        SDL_DestroyTexture(t);
        SDL_FreeSurface(text);
        drawn = true;
      }
    }
#endif
    if (overlay && !drawn) SDL_SetWindowTitle(window, ("kestrel  " + stats).c_str());
    ++frame_count;
    const bool last_frame = a.frames > 0 && frame_count >= a.frames;
    if (last_frame &&
        !a.screenshot.empty()) {  // what the window shows (overlay included), read back
      std::vector<uint8_t> shot(size_t(settings.width) * size_t(settings.height) * 3);
      if (SDL_RenderReadPixels(ren, nullptr, SDL_PIXELFORMAT_RGB24, shot.data(),
                               settings.width * 3) != 0)
        throw Error(ErrorCode::io_error,
                    fmt::format("view: cannot read the window back: {}", SDL_GetError()));
      write_png(a.screenshot, settings.width, settings.height, shot);
      fmt::print("wrote    {}\n", a.screenshot);
    }
    SDL_RenderPresent(ren);
    if (last_frame) running = false;
  }
  fmt::print("view     {} frames, last {:.1f} fps\n", frame_count, fps);
#ifdef KESTREL_HAVE_SDL2_TTF
  if (font) TTF_CloseFont(font);
  TTF_Quit();
#endif
  SDL_DestroyTexture(tex);
  SDL_DestroyRenderer(ren);
  SDL_DestroyWindow(window);
}

#else

void view(ViewArgs&) {
  throw Error(ErrorCode::unsupported,
              "view: this kestrel was built without SDL2 (apt-get install libsdl2-dev, rebuild)");
}

#endif

}  // namespace

Action add_view_command(CLI::App& cmd) {
  auto a = std::make_shared<ViewArgs>();
  a->p.res = "960x540";
  a->p.add_to(cmd);
  cmd.add_option("--view", a->view,
                 "Start view (the scene's .views.json or data/views; default front, else framing)");
  cmd.add_option("--path", a->path,
                 "Drive the camera along a path (JSON or orbit[:DEG]) over --frames frames");
  cmd.add_option("--frames", a->frames, "Close after this many frames (0 = when the window closes)")
      ->capture_default_str();
  cmd.add_option("--screenshot", a->screenshot,
                 "With --frames: write the last frame as the window shows it (PNG)");
  cmd.add_option("--stage", a->stage,
                 "Displayed stage: 1 noisy, 2 denoised, 3 upsampled, 4 reference")
      ->capture_default_str();
  cmd.add_flag("--no-overlay", a->no_overlay, "Start without the overlay (Tab toggles it)");
  cmd.add_option("--font", a->font, "TrueType font of the overlay")->capture_default_str();
  return [a] { view(*a); };
}

}  // namespace kestrel::cli
