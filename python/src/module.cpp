// The Python module `kestrel._kestrel` (re-exported by the package `kestrel`): kestrel's
// public API with numpy arrays in and out. kestrel::Error becomes the Python exception a
// user expects: OSError (FileNotFoundError) for files that cannot be opened or written,
// ValueError for malformed content and bad arguments, NotImplementedError for valid input
// kestrel does not handle.
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "arrays.h"
#include "bindings.h"
#include "kestrel/error.h"
#include "kestrel/parallel.h"
#include "kestrel/trace.h"
#include "queries.h"

namespace py = pybind11;
using namespace kestrel;

PYBIND11_MODULE(_kestrel, m) {
  m.doc() =
      "kestrel: CPU ray tracing (BVHs, SIMD traversal, path tracing, denoising, upsampling) from "
      "numpy.";
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const Error& e) {
      switch (e.code()) {
        case ErrorCode::file_not_found:
          PyErr_SetString(PyExc_FileNotFoundError, e.what());
          break;
        case ErrorCode::io_error:
          PyErr_SetString(PyExc_OSError, e.what());
          break;
        case ErrorCode::unsupported:
          PyErr_SetString(PyExc_NotImplementedError, e.what());
          break;
        default:
          PyErr_SetString(PyExc_ValueError, e.what());
          break;
      }
    } catch (const std::bad_alloc&) {
      PyErr_SetString(PyExc_MemoryError, "kestrel: out of memory");
    }
  });

  python::bind_geometry(m);
  python::bind_instances(m);
  python::bind_render(m);
  python::bind_images(m);

  m.def("hardware_thread_count", &hardware_thread_count);
  m.def(
      "host_isa", [] { return std::string(isa_name(host_isa())); },
      "The best instruction set of this CPU.");
  m.def("default_isa", [] { return std::string(isa_name(default_isa())); });
  m.def(
      "set_default_isa",
      [](const std::string& name) {
        const TraceOptions o = python::trace_options(name, std::nullopt);
        if (!o.isa) throw py::value_error("isa: expected sse2, avx2 or avx512");
        set_default_isa(*o.isa);
      },
      py::arg("isa"), "The ISA used when a call leaves it open (sse2, avx2, avx512).");
  m.def("isa_supported", [](const std::string& name) {
    auto isa = isa_from_name(name);
    if (!isa) throw py::value_error("isa: unknown ISA '" + name + "' (sse2, avx2, avx512)");
    return isa_supported(*isa);
  });
  m.def("_last_inputs", &python::last_inputs,
        "Addresses the last trace/occluded call read its arrays from (tests check zero-copy with "
        "it).");
}
