// Affine3's operations, the validity test of a transform and its inverse, and the
// instances file (the two-level scene's transforms, apart from the scene itself).
#include <fmt/format.h>

#include <cmath>
#include <sstream>

#include "core/file_io.h"
#include "kestrel/error.h"
#include "scene/transforms.h"

namespace kestrel {

Affine3 Affine3::translation(Vec3 t) {
  Affine3 a;
  a.m[3] = t.x, a.m[7] = t.y, a.m[11] = t.z;
  return a;
}

Affine3 Affine3::scaling(Vec3 s) {
  Affine3 a;
  a.m[0] = s.x, a.m[5] = s.y, a.m[10] = s.z;
  return a;
}

Affine3 Affine3::rotation_y(float degrees) {
  const double r = double(degrees) * 3.14159265358979323846 / 180.0;
  const float c = float(std::cos(r)), s = float(std::sin(r));
  Affine3 a;
  a.m[0] = c, a.m[2] = s;
  a.m[8] = -s, a.m[10] = c;
  return a;
}

Affine3 Affine3::operator*(const Affine3& b) const {
  Affine3 r;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 4; ++j) {
      double v = j == 3 ? m[4 * i + 3] : 0.0;
      for (int k = 0; k < 3; ++k) v += double(m[4 * i + k]) * b.m[4 * k + j];
      r.m[4 * i + j] = float(v);
    }
  }
  return r;
}

Vec3 Affine3::point(Vec3 p) const {
  return {m[0] * p.x + m[1] * p.y + m[2] * p.z + m[3], m[4] * p.x + m[5] * p.y + m[6] * p.z + m[7],
          m[8] * p.x + m[9] * p.y + m[10] * p.z + m[11]};
}

Vec3 Affine3::vector(Vec3 v) const {
  return {m[0] * v.x + m[1] * v.y + m[2] * v.z, m[4] * v.x + m[5] * v.y + m[6] * v.z,
          m[8] * v.x + m[9] * v.y + m[10] * v.z};
}

namespace {
double determinant(const Affine3& a) {
  const float* m = a.m;
  return double(m[0]) * (double(m[5]) * m[10] - double(m[6]) * m[9]) -
         double(m[1]) * (double(m[4]) * m[10] - double(m[6]) * m[8]) +
         double(m[2]) * (double(m[4]) * m[9] - double(m[5]) * m[8]);
}
}  // namespace

std::string transform_problem(const Affine3& a) {
  for (int i = 0; i < 12; ++i)
    if (!std::isfinite(a.m[i])) return fmt::format("transform entry m[{}] is {}", i, a.m[i]);
  // Singular relative to the size of its columns: |det| tiny against the product of their
  // norms, |det| > 1e-12 * prod |c_k|, tested squared (no square roots; the squares of
  // floats stay far inside double's range).
  double scale2 = 1;
  for (int c = 0; c < 3; ++c)
    scale2 *=
        double(a.m[c]) * a.m[c] + double(a.m[4 + c]) * a.m[4 + c] + double(a.m[8 + c]) * a.m[8 + c];
  const double det = determinant(a);
  if (!(scale2 > 0) || !(det * det > 1e-24 * scale2))
    return fmt::format("transform is singular (determinant {:g})", det);
  return {};
}

Affine3 inverse_of_valid(const Affine3& a) {
  const float* m = a.m;
  const double det = determinant(a), inv_det = 1.0 / det;
  double r[9];
  r[0] = (double(m[5]) * m[10] - double(m[6]) * m[9]) * inv_det;
  r[1] = (double(m[2]) * m[9] - double(m[1]) * m[10]) * inv_det;
  r[2] = (double(m[1]) * m[6] - double(m[2]) * m[5]) * inv_det;
  r[3] = (double(m[6]) * m[8] - double(m[4]) * m[10]) * inv_det;
  r[4] = (double(m[0]) * m[10] - double(m[2]) * m[8]) * inv_det;
  r[5] = (double(m[2]) * m[4] - double(m[0]) * m[6]) * inv_det;
  r[6] = (double(m[4]) * m[9] - double(m[5]) * m[8]) * inv_det;
  r[7] = (double(m[1]) * m[8] - double(m[0]) * m[9]) * inv_det;
  r[8] = (double(m[0]) * m[5] - double(m[1]) * m[4]) * inv_det;
  Affine3 out;
  for (int i = 0; i < 3; ++i) {
    double t = 0;
    for (int k = 0; k < 3; ++k) {
      out.m[4 * i + k] = float(r[3 * i + k]);
      t -= r[3 * i + k] * m[4 * k + 3];
    }
    out.m[4 * i + 3] = float(t);
  }
  return out;
}

Affine3 inverse(const Affine3& a) {
  if (const std::string p = transform_problem(a); !p.empty())
    throw Error(ErrorCode::invalid_argument, p);
  return inverse_of_valid(a);
}

std::vector<Affine3> load_instance_transforms(const std::string& path) {
  std::istringstream in(read_bounded_file(path, uint64_t(1) << 30, "instances file"));
  std::vector<Affine3> out;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    const size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    std::istringstream ss(line);
    float v[7];
    for (float& x : v)
      if (!(ss >> x))
        throw Error(
            ErrorCode::parse_error,
            fmt::format("{}:{}: expected 7 numbers 'sx sy sz tx ty tz rot_y_deg'", path, number));
    std::string extra;
    if (ss >> extra)
      throw Error(ErrorCode::parse_error,
                  fmt::format("{}:{}: unexpected '{}' after 7 numbers", path, number, extra));
    const Affine3 a = Affine3::translation({v[3], v[4], v[5]}) * Affine3::rotation_y(v[6]) *
                      Affine3::scaling({v[0], v[1], v[2]});
    if (const std::string p = transform_problem(a); !p.empty())
      throw Error(ErrorCode::invalid_geometry, fmt::format("{}:{}: {}", path, number, p));
    out.push_back(a);
  }
  return out;
}

}  // namespace kestrel
