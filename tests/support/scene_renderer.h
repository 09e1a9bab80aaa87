// A renderer over a test Scene (made an Asset: each mesh one identity instance), kept beside it.
#pragma once
#include <optional>
#include <utility>

#include "kestrel/asset.h"
#include "kestrel/render.h"

namespace kestrel::test {

struct AssetHolder {
  Asset asset;
};
struct SceneRenderer : private AssetHolder, public Renderer {
  explicit SceneRenderer(Scene scene, std::optional<Environment> env = std::nullopt)
      : AssetHolder{Asset::from_scene(std::move(scene))}, Renderer(asset.scene(), std::move(env)) {}
};

}  // namespace kestrel::test
