// What the geometry and instance bindings share (python/src/geometry.cpp): record dtypes,
// the one batch-query helper, meshes and transforms from arrays, commit timings.
#pragma once
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <optional>
#include <span>
#include <string>

#include "arrays.h"
#include "bindings.h"
#include "kestrel/instances.h"
#include "kestrel/trace.h"

namespace kestrel::python {

py::dtype hit_dtype();
py::dtype instance_hit_dtype();
std::span<const Ray> ray_span(const py::array_t<float, py::array::c_style>& rays);
/// out= checked (dtype, shape, contiguous, writable) or a new record array of n.
py::array output_records(py::object out, const py::dtype& dtype, size_t n, const char* what);
/// A record array as a dict of its fields (views).
py::dict fields_of(const py::array& records);
/// A mesh from numpy arrays (ValueError for bad shapes, indices, NaN per nan_policy).
TriangleMesh mesh_from_arrays(py::handle vertices, py::handle indices, py::handle normals,
                              py::handle uvs, const std::string& name,
                              const std::string& nan_policy, uint32_t material,
                              py::handle colors = py::none());
const TriangleMesh& mesh_at(const Scene& s, size_t mesh);
/// A (3, 4) or (4, 4) transform; ValueError naming `name` otherwise.
Affine3 affine_from(py::handle object, const char* name);
py::array_t<float> affine_array(const Affine3& t);
py::dict commit_dict(const CommitStats& s);

// One batch query from Python, written once for Accel and InstancedScene, closest and any
// hit: the rays checked and read in place, the output records (out= or a new array) written
// in place by query(rays, records, options) with the GIL released.
template <class Record, class Query>
py::array ray_query(py::handle rays, py::object out, const py::dtype& dtype, const char* what,
                    const std::optional<std::string>& isa, std::optional<bool> packets, int threads,
                    Query&& query) {
  clear_inputs();
  const auto r = input_array<float>(rays, "rays", {-1, 8});
  const TraceOptions options = trace_options(isa, packets);
  py::array records = output_records(out, dtype, size_t(r.shape(0)), what);
  const std::span<Record> result(static_cast<Record*>(records.mutable_data()), size_t(r.shape(0)));
  without_gil(threads, [&] {
    query(ray_span(r), result, options);
    return 0;
  });
  return records;
}

void bind_instances(py::module_& m);  // InstancedScene (python/src/instances.cpp)

}  // namespace kestrel::python
