// kestrel public API: plain value types shared by every module.
#pragma once
#include <cstdint>

namespace kestrel {

/// A 2-component float vector (texture coordinates).
struct Vec2 {
  float x = 0, y = 0;
};

/// A 3-component float vector: positions and directions in world units, or linear RGB.
struct Vec3 {
  float x = 0, y = 0, z = 0;
  float operator[](int axis) const { return axis == 0 ? x : (axis == 1 ? y : z); }
  float& operator[](int axis) { return axis == 0 ? x : (axis == 1 ? y : z); }
  bool operator==(const Vec3&) const = default;
};

/// An axis-aligned box; empty when lo > hi on any axis (the default is empty).
struct Bounds3 {
  Vec3 lo{1e30f, 1e30f, 1e30f};
  Vec3 hi{-1e30f, -1e30f, -1e30f};
};

}  // namespace kestrel
