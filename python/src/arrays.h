// Numpy arrays at the boundary of the Python module: checking inputs (dtype, shape,
// contiguity) so they are used in place, and handing kestrel's own buffers to numpy without
// a copy. Every check names the argument, as kestrel::Error names the file.
#pragma once
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <initializer_list>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "kestrel/io.h"

namespace kestrel::python {

namespace py = pybind11;

/// Where the last call on this thread read each of its array inputs from (name -> address),
/// so tests can check that a C-contiguous input of the right dtype was not copied.
void note_input(const char* name, const void* data);
void clear_inputs();
py::dict last_inputs();

/// An input array of dtype T and the given shape (-1 = any extent; a shape of one entry
/// fewer than given is accepted where `allow_missing_last` and the last extent is 1, e.g.
/// (H, W) for a one-channel image). A numpy array of another dtype is a TypeError naming the
/// argument; a Python list is converted; a non-contiguous array is copied once; a wrong
/// shape is a ValueError. C-contiguous arrays of dtype T are used in place (note_input).
py::array checked_array(py::handle object, const char* name, const py::dtype& dtype,
                        const char* dtype_name, std::initializer_list<py::ssize_t> shape,
                        bool allow_missing_last = false);

template <class T>
py::array_t<T, py::array::c_style> input_array(py::handle object, const char* name,
                                               std::initializer_list<py::ssize_t> shape,
                                               bool allow_missing_last = false);

/// A float image (H, W, C) from a float32 array of shape (H, W, C) or (H, W); `channels`
/// > 0 requires that count. Copied: FloatImage owns its pixels. NaN/Inf entries are a
/// ValueError when `finite` is set.
FloatImage image_from_array(py::handle object, const char* name, int channels = 0,
                            bool finite = false);

/// A numpy array over a vector's storage, which the array then owns (no copy).
template <class T>
py::array_t<T> take_vector(std::vector<T>&& values, std::vector<py::ssize_t> shape) {
  auto* owned = new std::vector<T>(std::move(values));
  py::capsule free_when_done(owned, [](void* p) { delete static_cast<std::vector<T>*>(p); });
  return py::array_t<T>(std::move(shape), owned->data(), free_when_done);
}

/// An image as a (H, W, C) float32 array over its pixels (no copy; the array owns them).
py::array_t<float> take_image(FloatImage&& image);

/// A fresh (H, W, C) float32 array holding a copy of the image (for images kestrel reuses).
py::array_t<float> copy_image(const FloatImage& image);

/// Writes an image into a caller's `out` array (float32, C-contiguous, the image's shape)
/// and returns it; when `out` is None, returns take_image(image).
py::array_t<float> image_out(FloatImage&& image, py::object out, const char* name);

/// (x, y, z) from a sequence of three numbers.
Vec3 vec3_from(py::handle object, const char* name);

}  // namespace kestrel::python

namespace kestrel::python {

template <class T>
py::array_t<T, py::array::c_style> input_array(py::handle object, const char* name,
                                               std::initializer_list<py::ssize_t> shape,
                                               bool allow_missing_last) {
  const char* dtype_name = std::is_same_v<T, float>      ? "float32"
                           : std::is_same_v<T, uint32_t> ? "uint32"
                           : std::is_same_v<T, uint8_t>  ? "uint8"
                           : std::is_same_v<T, double>   ? "float64"
                                                         : "the expected dtype";
  return py::array_t<T, py::array::c_style>::ensure(
      checked_array(object, name, py::dtype::of<T>(), dtype_name, shape, allow_missing_last));
}

}  // namespace kestrel::python
