// The Python module's parts: each binds one area of the public API into the module.
#pragma once
#include <pybind11/pybind11.h>

#include <memory>
#include <optional>
#include <string>

#include "kestrel/bvh.h"
#include "kestrel/instances.h"
#include "kestrel/scene.h"
#include "kestrel/trace.h"

namespace kestrel::python {

namespace py = pybind11;

void bind_geometry(py::module_& m);  // Scene, Accel, trace, occluded, BVH metrics, InstancedScene
void bind_render(py::module_& m);    // Camera, Renderer, Denoiser, Upscaler, Pipeline
void bind_images(py::module_& m);    // EXR, PFM, PNG, rays/hits files, tone map

/// A two-level scene, optionally with the glTF animation that poses it (shared with the
/// renderers that reference it).
struct PyInstancedScene {
  InstancedScene scene;
  std::optional<GltfInstances> gltf;
};

/// Runs `body` with the GIL released and the library limited to `threads` workers (0 = all).
template <class F>
auto without_gil(int threads, F&& body);

/// Trace choices from the Python arguments: isa None/"auto" = the default; a name this CPU
/// lacks is a ValueError.
TraceOptions trace_options(const std::optional<std::string>& isa, std::optional<bool> packets);

}  // namespace kestrel::python

#include "kestrel/parallel.h"

namespace kestrel::python {

template <class F>
auto without_gil(int threads, F&& body) {
  if (threads < 0) throw py::value_error("threads: must be >= 0 (0 = all)");
  py::gil_scoped_release release;
  std::unique_ptr<ThreadLimit> limit;
  if (threads > 0) limit = std::make_unique<ThreadLimit>(threads);
  return body();
}

}  // namespace kestrel::python
