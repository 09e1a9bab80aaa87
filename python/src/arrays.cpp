// Numpy arrays at the boundary of the Python module (see arrays.h).
#include "arrays.h"

#include <fmt/format.h>

#include <cmath>
#include <cstring>
#include <map>

namespace kestrel::python {

namespace {

thread_local std::map<std::string, uintptr_t> inputs_read;

std::string shape_text(const py::ssize_t* dims, size_t n) {
  std::string s = "(";
  for (size_t i = 0; i < n; ++i) s += fmt::format("{}{}", i ? ", " : "", dims[i]);
  return s + (n == 1 ? ",)" : ")");
}

std::string expected_text(std::initializer_list<py::ssize_t> shape) {
  std::string s = "(";
  size_t i = 0;
  for (py::ssize_t d : shape)
    s += fmt::format("{}{}", i++ ? ", " : "", d < 0 ? std::string("N") : std::to_string(d));
  return s + (shape.size() == 1 ? ",)" : ")");
}

}  // namespace

void note_input(const char* name, const void* data) {
  inputs_read[name] = reinterpret_cast<uintptr_t>(data);
}
void clear_inputs() {
  inputs_read.clear();
}
py::dict last_inputs() {
  py::dict d;
  for (const auto& [name, address] : inputs_read) d[py::str(name)] = py::int_(address);
  return d;
}

py::array checked_array(py::handle object, const char* name, const py::dtype& dtype,
                        const char* dtype_name, std::initializer_list<py::ssize_t> shape,
                        bool allow_missing_last) {
  if (object.is_none())
    throw py::type_error(fmt::format("{}: expected a {} array, got None", name, dtype_name));
  py::array a;
  if (py::isinstance<py::array>(object)) {
    a = py::reinterpret_borrow<py::array>(object);
    if (!a.dtype().is(dtype))
      throw py::type_error(fmt::format(
          "{}: expected dtype {}, got {} (convert with .astype(numpy.{}))", name, dtype_name,
          py::str(static_cast<const py::handle&>(a.dtype())).cast<std::string>(), dtype_name));
  } else {
    // A list or other sequence: converted (a copy is unavoidable); a failure names the argument.
    try {
      a = py::array::ensure(py::module_::import("numpy").attr("asarray")(object, dtype));
    } catch (const py::error_already_set& e) {
      throw py::type_error(
          fmt::format("{}: expected a {} array, got {}", name, dtype_name,
                      std::string(py::str(py::type::of(object).attr("__name__")))));
    }
  }
  const size_t ndim = size_t(a.ndim());
  bool ok = ndim == shape.size() ||
            (allow_missing_last && ndim + 1 == shape.size() && *(shape.end() - 1) == 1);
  if (ok) {
    size_t i = 0;
    for (py::ssize_t want : shape) {
      if (i >= ndim) break;
      if (want >= 0 && a.shape(py::ssize_t(i)) != want) ok = false;
      ++i;
    }
  }
  if (!ok)
    throw py::value_error(fmt::format("{}: expected shape {}, got {}", name, expected_text(shape),
                                      shape_text(a.shape(), ndim)));
  if (!(a.flags() & py::array::c_style))
    a = py::array::ensure(a, py::array::c_style | py::array::forcecast);
  note_input(name, a.data());
  return a;
}

FloatImage image_from_array(py::handle object, const char* name, int channels, bool finite) {
  const bool planar =
      py::isinstance<py::array>(object) && py::reinterpret_borrow<py::array>(object).ndim() == 2;
  py::array a = planar
                    ? checked_array(object, name, py::dtype::of<float>(), "float32", {-1, -1})
                    : checked_array(object, name, py::dtype::of<float>(), "float32", {-1, -1, -1});
  const int c = planar ? 1 : int(a.shape(2));
  if (channels > 0 && c != channels)
    throw py::value_error(fmt::format("{}: expected {} channels (shape (H, W, {})), got {}", name,
                                      channels, channels, c));
  if (a.shape(0) <= 0 || a.shape(1) <= 0 || a.shape(0) > 65536 || a.shape(1) > 65536)
    throw py::value_error(
        fmt::format("{}: image size {}x{} is not in 1..65536", name, a.shape(1), a.shape(0)));
  FloatImage image(int(a.shape(1)), int(a.shape(0)), c);
  std::memcpy(image.pixels.data(), a.data(), image.pixels.size() * sizeof(float));
  if (finite)
    for (size_t i = 0; i < image.pixels.size(); ++i)
      if (!std::isfinite(image.pixels[i]))
        throw py::value_error(fmt::format("{}: non-finite value at pixel ({}, {})", name,
                                          (i / size_t(c)) % size_t(image.width),
                                          i / size_t(c) / size_t(image.width)));
  return image;
}

py::array_t<float> take_image(FloatImage&& image) {
  const py::ssize_t h = image.height, w = image.width, c = image.channels;
  return take_vector(std::move(image.pixels), {h, w, c});
}

py::array_t<float> copy_image(const FloatImage& image) {
  py::array_t<float> a(
      {py::ssize_t(image.height), py::ssize_t(image.width), py::ssize_t(image.channels)});
  std::memcpy(a.mutable_data(), image.pixels.data(), image.pixels.size() * sizeof(float));
  return a;
}

py::array_t<float> image_out(FloatImage&& image, py::object out, const char* name) {
  if (out.is_none()) return take_image(std::move(image));
  if (!py::isinstance<py::array>(out))
    throw py::type_error(fmt::format("{}: expected a float32 array", name));
  auto a = py::reinterpret_borrow<py::array>(out);
  if (!a.dtype().is(py::dtype::of<float>()))
    throw py::type_error(
        fmt::format("{}: expected dtype float32, got {}", name,
                    py::str(static_cast<const py::handle&>(a.dtype())).cast<std::string>()));
  if (!(a.flags() & py::array::c_style) || !a.writeable())
    throw py::value_error(fmt::format("{}: must be a writeable C-contiguous array", name));
  const bool shape_ok = (a.ndim() == 3 && a.shape(0) == image.height && a.shape(1) == image.width &&
                         a.shape(2) == image.channels) ||
                        (a.ndim() == 2 && image.channels == 1 && a.shape(0) == image.height &&
                         a.shape(1) == image.width);
  if (!shape_ok)
    throw py::value_error(fmt::format("{}: expected shape ({}, {}, {}), got {}", name, image.height,
                                      image.width, image.channels,
                                      shape_text(a.shape(), size_t(a.ndim()))));
  std::memcpy(a.mutable_data(), image.pixels.data(), image.pixels.size() * sizeof(float));
  return py::reinterpret_borrow<py::array_t<float>>(out);
}

Vec3 vec3_from(py::handle object, const char* name) {
  // Any three numbers (a tuple, a list, a float64 array): a point or direction, not bulk data.
  py::array_t<float, py::array::c_style | py::array::forcecast> a;
  try {
    a = py::module_::import("numpy").attr("asarray")(object, py::dtype::of<float>());
  } catch (const py::error_already_set&) {
    throw py::type_error(fmt::format("{}: expected three numbers", name));
  }
  if (a.ndim() != 1 || a.shape(0) != 3)
    throw py::value_error(fmt::format("{}: expected three numbers", name));
  const float* p = a.data();
  return Vec3{p[0], p[1], p[2]};
}

}  // namespace kestrel::python
