// kestrel public API: plain value types shared by every module.
#pragma once
#include <cmath>
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

/// Vector arithmetic, componentwise where both sides are vectors.
inline Vec3 operator+(Vec3 a, Vec3 b) {
  return {a.x + b.x, a.y + b.y, a.z + b.z};
}
inline Vec3 operator-(Vec3 a, Vec3 b) {
  return {a.x - b.x, a.y - b.y, a.z - b.z};
}
inline Vec3 operator*(Vec3 a, Vec3 b) {
  return {a.x * b.x, a.y * b.y, a.z * b.z};
}
inline Vec3 operator*(Vec3 a, float s) {
  return {a.x * s, a.y * s, a.z * s};
}
inline Vec3 operator*(float s, Vec3 a) {
  return a * s;
}
inline Vec3 operator/(Vec3 a, float s) {
  return a * (1.0f / s);
}
inline Vec3 operator-(Vec3 a) {
  return {-a.x, -a.y, -a.z};
}
/// Dot and cross products, Euclidean length, and a / length(a) (NaN for a zero vector).
inline float dot(Vec3 a, Vec3 b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
inline Vec3 cross(Vec3 a, Vec3 b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline float length(Vec3 a) {
  return std::sqrt(dot(a, a));
}
inline Vec3 normalize(Vec3 a) {
  return a / length(a);
}

/// An axis-aligned box; empty when lo > hi on any axis (the default is empty).
struct Bounds3 {
  Vec3 lo{1e30f, 1e30f, 1e30f};
  Vec3 hi{-1e30f, -1e30f, -1e30f};
};

}  // namespace kestrel
