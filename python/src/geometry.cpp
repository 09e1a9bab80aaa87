// Python bindings of geometry and ray queries: scenes from files or numpy arrays, BVH builds
// and their metrics, batch trace / occluded over (N, 8) float32 rays in the `.rays` record
// layout (used in place), and two-level InstancedScenes with (3, 4) / (4, 4) transforms.
#include <fmt/format.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <cmath>
#include <cstddef>
#include <cstring>

#include "arrays.h"
#include "bindings.h"
#include "core/timer.h"
#include "geometry/prim_ref.h"
#include "kestrel/error.h"
#include "kestrel/instances.h"
#include "queries.h"

namespace kestrel::python {

// The (N, 8) float32 rays array is read in place as Ray records, and the hits array that
// numpy allocates is written in place as Hit records: both layouts are fixed here.
static_assert(sizeof(Ray) == 32 && offsetof(Ray, dir) == 12 && offsetof(Ray, tmin) == 24 &&
              offsetof(Ray, tmax) == 28);
static_assert(sizeof(Hit) == 16 && offsetof(Hit, prim_id) == 4 && offsetof(Hit, u) == 8 &&
              offsetof(Hit, v) == 12);
static_assert(sizeof(InstanceHit) == 20 && offsetof(InstanceHit, instance_id) == 8 &&
              offsetof(InstanceHit, v) == 16);
static_assert(sizeof(Vec3) == 12 && sizeof(Vec2) == 8);

TraceOptions trace_options(const std::optional<std::string>& isa, std::optional<bool> packets) {
  TraceOptions o;
  o.packets = packets;
  if (isa && *isa != "auto") {
    o.isa = isa_from_name(*isa);
    if (!o.isa)
      throw py::value_error(fmt::format("isa: unknown ISA '{}' (auto, sse2, avx2, avx512)", *isa));
    if (!isa_supported(*o.isa))
      throw py::value_error(fmt::format("isa: '{}' is not supported by this CPU (best: {})", *isa,
                                        isa_name(host_isa())));
  }
  return o;
}

namespace {

py::object numpy() {
  return py::module_::import("numpy");
}

std::string dtype_text(const py::dtype& d) {
  return py::str(static_cast<const py::handle&>(d)).cast<std::string>();
}

}  // namespace

py::dtype hit_dtype() {
  py::dict spec;
  spec["names"] = py::make_tuple("t", "prim_id", "u", "v");
  spec["formats"] = py::make_tuple("<f4", "<u4", "<f4", "<f4");
  spec["offsets"] = py::make_tuple(0, 4, 8, 12);
  spec["itemsize"] = 16;
  return py::dtype::from_args(spec);
}

py::dtype instance_hit_dtype() {
  py::dict spec;
  spec["names"] = py::make_tuple("t", "prim_id", "instance_id", "u", "v");
  spec["formats"] = py::make_tuple("<f4", "<u4", "<u4", "<f4", "<f4");
  spec["offsets"] = py::make_tuple(0, 4, 8, 12, 16);
  spec["itemsize"] = 20;
  return py::dtype::from_args(spec);
}

std::span<const Ray> ray_span(const py::array_t<float, py::array::c_style>& rays) {
  return {reinterpret_cast<const Ray*>(rays.data()), size_t(rays.shape(0))};
}

// A caller's out= array (checked: dtype, shape (n,), C-contiguous, writeable) or a new one.
py::array output_records(py::object out, const py::dtype& dtype, size_t n, const char* what) {
  if (out.is_none())
    return py::array(dtype, std::vector<py::ssize_t>{py::ssize_t(n)}, std::vector<py::ssize_t>{});
  if (!py::isinstance<py::array>(out))
    throw py::type_error(fmt::format("out: expected a numpy array of {}", what));
  auto a = py::reinterpret_borrow<py::array>(out);
  if (!a.dtype().equal(dtype))
    throw py::type_error(fmt::format("out: expected dtype {} ({}), got {}", dtype_text(dtype), what,
                                     dtype_text(a.dtype())));
  if (a.ndim() != 1 || size_t(a.shape(0)) != n)
    throw py::value_error(fmt::format("out: expected shape ({},), one record per ray", n));
  if (!(a.flags() & py::array::c_style) || !a.writeable())
    throw py::value_error("out: must be a writeable C-contiguous array");
  note_input("out", a.data());
  return a;
}

py::dict fields_of(const py::array& records) {
  py::dict d;
  for (py::handle name : records.dtype().attr("names")) d[name] = records[name];
  return d;
}

py::dict report_dict(const ValidationReport& r) {
  py::dict d;
  d["triangles"] = r.triangle_count;
  d["valid"] = r.valid_triangle_count;
  d["nonfinite"] = r.nonfinite_triangle_count;
  d["bad_index"] = r.bad_index_triangle_count;
  d["degenerate"] = r.degenerate_triangle_count;
  d["empty_meshes"] = r.empty_mesh_count;
  d["summary"] = r.summary();
  return d;
}

py::tuple bounds_tuple(const Bounds3& b) {
  return py::make_tuple(py::make_tuple(b.lo.x, b.lo.y, b.lo.z),
                        py::make_tuple(b.hi.x, b.hi.y, b.hi.z));
}

BuildConfig build_config(const std::optional<std::string>& builder,
                         const std::optional<std::string>& quality, const std::string& layout,
                         uint32_t max_leaf_size, float traversal_cost, float intersection_cost,
                         uint32_t bins, uint32_t morton_bits, double expected_rays) {
  BuildConfig c;
  if (builder) {
    c.builder = builder_from_name(*builder);
    if (!c.builder)
      throw py::value_error(fmt::format(
          "builder: unknown builder '{}' (median, sweep, binned, lbvh, spatial, treelet)",
          *builder));
  }
  if (quality) {
    auto q = quality_from_name(*quality);
    if (!q)
      throw py::value_error(
          fmt::format("quality: unknown quality '{}' (fast, balanced, high, auto)", *quality));
    c.quality = *q;
  }
  auto l = layout_from_name(layout);
  if (!l)
    throw py::value_error(
        fmt::format("layout: unknown layout '{}' (auto, bvh2, bvh4, bvh8)", layout));
  c.layout = *l;
  c.max_leaf_size = max_leaf_size;
  c.traversal_cost = traversal_cost;
  c.intersection_cost = intersection_cost;
  c.bin_count = bins;
  c.morton_bits = morton_bits;
  c.expected_rays = expected_rays;
  check_build_config(c);  // kestrel::Error(invalid_argument) -> ValueError naming the field
  return c;
}

// A mesh from numpy arrays. Out-of-range indices are a ValueError (a user's array, not a
// file: nothing to skip silently); non-finite vertices follow nan_policy.
TriangleMesh mesh_from_arrays(py::handle vertices, py::handle indices, py::handle normals,
                              py::handle uvs, const std::string& name,
                              const std::string& nan_policy, uint32_t material, py::handle colors) {
  if (nan_policy != "warn" && nan_policy != "raise" && nan_policy != "ignore")
    throw py::value_error(fmt::format("nan_policy: '{}' is not warn, raise or ignore", nan_policy));
  auto v = input_array<float>(vertices, "vertices", {-1, 3});
  auto i = input_array<uint32_t>(indices, "indices", {-1, 3});
  const size_t vertex_count = size_t(v.shape(0)), triangle_count = size_t(i.shape(0));
  if (vertex_count >= size_t(invalid_id))
    throw py::value_error("vertices: more than 2^32 - 1 vertices");
  TriangleMesh mesh;
  mesh.name = name;
  mesh.positions.resize(vertex_count);
  std::memcpy(static_cast<void*>(mesh.positions.data()), v.data(), vertex_count * sizeof(Vec3));
  mesh.indices.assign(i.data(), i.data() + 3 * triangle_count);
  for (size_t k = 0; k < mesh.indices.size(); ++k)
    if (mesh.indices[k] >= vertex_count)
      throw py::value_error(
          fmt::format("indices: row {} refers to vertex {}, but there are {} vertices", k / 3,
                      mesh.indices[k], vertex_count));
  if (!normals.is_none()) {
    auto n = input_array<float>(normals, "normals", {py::ssize_t(vertex_count), 3});
    mesh.normals.resize(vertex_count);
    std::memcpy(static_cast<void*>(mesh.normals.data()), n.data(), vertex_count * sizeof(Vec3));
  }
  if (!uvs.is_none()) {
    auto t = input_array<float>(uvs, "uvs", {py::ssize_t(vertex_count), 2});
    mesh.uvs.resize(vertex_count);
    std::memcpy(static_cast<void*>(mesh.uvs.data()), t.data(), vertex_count * sizeof(Vec2));
  }
  if (!colors.is_none()) {  // linear RGB in [0, 1] per vertex
    auto c = input_array<float>(colors, "colors", {py::ssize_t(vertex_count), 3});
    mesh.colors.resize(vertex_count);
    std::memcpy(static_cast<void*>(mesh.colors.data()), c.data(), vertex_count * sizeof(Vec3));
    for (const Vec3& x : mesh.colors)
      if (!(x.x >= 0 && x.x <= 1 && x.y >= 0 && x.y <= 1 && x.z >= 0 && x.z <= 1))
        throw py::value_error("colors: every value must be in [0, 1]");
  }
  mesh.material_ids.assign(triangle_count, material);
  if (nan_policy != "ignore") {
    size_t bad = 0;
    for (const Vec3& p : mesh.positions)
      bad += !(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z));
    if (bad > 0) {
      const std::string what = fmt::format(
          "vertices: {} of {} vertices have a NaN or Inf coordinate; triangles using them are "
          "skipped",
          bad, vertex_count);
      if (nan_policy == "raise") throw py::value_error(what);
      PyErr_WarnEx(PyExc_RuntimeWarning, what.c_str(), 1);
    }
  }
  return mesh;
}

template <class T>
py::array_t<T> copy_rows(const std::vector<T>& values, py::ssize_t rows, py::ssize_t columns) {
  py::array_t<T> a({rows, columns});
  if (!values.empty()) std::memcpy(a.mutable_data(), values.data(), values.size() * sizeof(T));
  return a;
}

const TriangleMesh& mesh_at(const Scene& s, size_t mesh) {
  if (mesh >= s.meshes.size())
    throw py::index_error(
        fmt::format("mesh: index {} out of range ({} meshes)", mesh, s.meshes.size()));
  return s.meshes[mesh];
}

py::array_t<float> copy_vec3s(const std::vector<Vec3>& v) {
  py::array_t<float> a({py::ssize_t(v.size()), py::ssize_t(3)});
  if (!v.empty()) std::memcpy(a.mutable_data(), v.data(), v.size() * sizeof(Vec3));
  return a;
}

Affine3 affine_from(py::handle object, const char* name) {
  py::array_t<float, py::array::c_style | py::array::forcecast> a;
  try {
    a = numpy().attr("asarray")(object, py::dtype::of<float>());
  } catch (const py::error_already_set&) {
    throw py::type_error(fmt::format("{}: expected a (3, 4) or (4, 4) array of numbers", name));
  }
  if (a.ndim() != 2 || a.shape(1) != 4 || (a.shape(0) != 3 && a.shape(0) != 4))
    throw py::value_error(fmt::format("{}: expected shape (3, 4) or (4, 4)", name));
  const float* p = a.data();
  if (a.shape(0) == 4 && !(p[12] == 0 && p[13] == 0 && p[14] == 0 && p[15] == 1))
    throw py::value_error(
        fmt::format("{}: the last row of a (4, 4) transform must be (0, 0, 0, 1)", name));
  Affine3 t;
  std::memcpy(t.m, p, sizeof(t.m));  // row-major 3 x 4, as Affine3
  const std::string problem = transform_problem(t);
  if (!problem.empty()) throw py::value_error(fmt::format("{}: {}", name, problem));
  return t;
}

py::array_t<float> affine_array(const Affine3& t) {
  py::array_t<float> a({py::ssize_t(3), py::ssize_t(4)});
  std::memcpy(a.mutable_data(), t.m, sizeof(t.m));
  return a;
}

py::dict commit_dict(const CommitStats& s) {
  py::dict d;
  d["total_ms"] = s.total_ms;
  d["tlas_ms"] = s.tlas_ms;
  d["blas_build_ms"] = s.blas_build_ms;
  d["blas_refit_ms"] = s.blas_refit_ms;
  d["blas_builds"] = s.blas_builds;
  d["blas_refits"] = s.blas_refits;
  d["instances"] = s.instances;
  return d;
}

void bind_geometry(py::module_& m) {
  m.attr("hit_dtype") = hit_dtype();
  m.attr("instance_hit_dtype") = instance_hit_dtype();
  m.attr("invalid_id") = invalid_id;

  py::class_<Scene, std::shared_ptr<Scene>>(
      m, "Scene", "Triangle meshes, materials and textures (kestrel::Scene).")
      .def(py::init<>(), "An empty scene; add meshes with add_mesh.")
      .def_static(
          "from_arrays",
          [](py::handle vertices, py::handle indices, py::handle normals, py::handle uvs,
             const std::string& name, const std::string& nan_policy) {
            auto s = std::make_shared<Scene>();
            s->source = "arrays";
            s->materials.push_back(Material{.name = "default"});
            s->meshes.push_back(
                mesh_from_arrays(vertices, indices, normals, uvs, name, nan_policy, 0));
            return s;
          },
          py::arg("vertices"), py::arg("indices"), py::arg("normals") = py::none(),
          py::arg("uvs") = py::none(), py::arg("name") = "mesh", py::arg("nan_policy") = "warn",
          "A one-mesh scene from vertices (N, 3) float32 and indices (M, 3) uint32 (copied into "
          "the scene).")
      .def(
          "add_mesh",
          [](Scene& s, py::handle vertices, py::handle indices, py::handle normals, py::handle uvs,
             const std::string& name, int material, const std::string& nan_policy,
             py::handle colors) {
            if (s.materials.empty()) s.materials.push_back(Material{.name = "default"});
            if (material < 0 || size_t(material) >= s.materials.size())
              throw py::value_error(fmt::format("material: {} is not a material index (0..{})",
                                                material, s.materials.size() - 1));
            s.meshes.push_back(mesh_from_arrays(vertices, indices, normals, uvs, name, nan_policy,
                                                uint32_t(material), colors));
            return s.meshes.size() - 1;
          },
          py::arg("vertices"), py::arg("indices"), py::arg("normals") = py::none(),
          py::arg("uvs") = py::none(), py::arg("name") = "mesh", py::arg("material") = 0,
          py::arg("nan_policy") = "warn", py::arg("colors") = py::none(),
          "Appends a mesh (prim ids continue after the previous meshes'); returns its index. "
          "colors: (N, 3) linear RGB in [0, 1] per vertex, multiplying the material's base "
          "colour.")
      .def(
          "add_material",
          [](Scene& s, const std::string& name, py::handle base_color, float metallic,
             float roughness, float specular, py::handle emission, float alpha, float transmission,
             float ior, bool thin_walled) {
            Material mat{.name = name};
            if (!(alpha >= 0 && alpha <= 1))
              throw py::value_error(
                  fmt::format("material '{}': alpha {} is not in [0, 1]", name, alpha));
            if (!(transmission >= 0 && transmission <= 1))
              throw py::value_error(fmt::format("material '{}': transmission {} is not in [0, 1]",
                                                name, transmission));
            if (!(ior >= 1) || !std::isfinite(ior))
              throw py::value_error(fmt::format(
                  "material '{}': ior {} is not a finite index of refraction >= 1", name, ior));
            mat.transmission = transmission;
            mat.ior = ior;
            mat.thin_walled = thin_walled;
            mat.alpha = alpha;
            if (alpha < 1) mat.alpha_mode = Material::AlphaMode::blend;
            mat.base_color = vec3_from(base_color, "base_color");
            mat.emission = vec3_from(emission, "emission");
            mat.metallic = metallic;
            mat.roughness = roughness;
            mat.specular = specular;
            for (float x : {mat.base_color.x, mat.base_color.y, mat.base_color.z, mat.emission.x,
                            mat.emission.y, mat.emission.z, metallic, roughness, specular})
              if (!std::isfinite(x) || x < 0)
                throw py::value_error(
                    fmt::format("material '{}': values must be finite and >= 0", name));
            if (metallic > 1 || roughness > 1 || specular > 1)
              throw py::value_error(fmt::format(
                  "material '{}': metallic, roughness and specular are in [0, 1]", name));
            if (s.materials.empty()) s.materials.push_back(Material{.name = "default"});
            s.materials.push_back(mat);
            return s.materials.size() - 1;
          },
          py::arg("name"), py::arg("base_color") = py::make_tuple(0.8, 0.8, 0.8),
          py::arg("metallic") = 0.0f, py::arg("roughness") = 1.0f, py::arg("specular") = 0.0f,
          py::arg("emission") = py::make_tuple(0, 0, 0), py::arg("alpha") = 1.0f,
          py::arg("transmission") = 0.0f, py::arg("ior") = 1.5f, py::arg("thin_walled") = false,
          "Appends a metallic-roughness material; returns its index for add_mesh(material=...). "
          "alpha < 1: a surface that a fraction alpha of the rays meeting it sees (stochastic "
          "transparency). transmission > 0: glass (smooth or rough by roughness, tinted by "
          "base_color) refracting at ior, the mesh a solid whose counter-clockwise faces are "
          "its outside; thin_walled: a sheet light goes straight through.")
      .def_readonly("source", &Scene::source)
      .def_readonly("warnings", &Scene::warnings)
      .def_property_readonly("triangle_count", &Scene::triangle_count)
      .def_property_readonly("mesh_count", [](const Scene& s) { return s.meshes.size(); })
      .def_property_readonly("material_count", [](const Scene& s) { return s.materials.size(); })
      .def_property_readonly("texture_count", [](const Scene& s) { return s.textures.size(); })
      .def_property_readonly("mesh_names",
                             [](const Scene& s) {
                               std::vector<std::string> n;
                               for (const auto& mesh : s.meshes) n.push_back(mesh.name);
                               return n;
                             })
      .def(
          "vertices",
          [](const Scene& s, size_t mesh) { return copy_vec3s(mesh_at(s, mesh).positions); },
          py::arg("mesh") = 0, "A copy of a mesh's positions, (N, 3) float32.")
      .def(
          "normals",
          [](const Scene& s, size_t mesh) { return copy_vec3s(mesh_at(s, mesh).normals); },
          py::arg("mesh") = 0,
          "A copy of a mesh's per-vertex normals, (N, 3) float32 (N = 0 when it has none).")
      .def(
          "uvs",
          [](const Scene& s, size_t mesh) {
            const auto& uv = mesh_at(s, mesh).uvs;
            py::array_t<float> a({py::ssize_t(uv.size()), py::ssize_t(2)});
            if (!uv.empty()) std::memcpy(a.mutable_data(), uv.data(), uv.size() * sizeof(Vec2));
            return a;
          },
          py::arg("mesh") = 0,
          "A copy of a mesh's texture coordinates, (N, 2) float32 (glTF convention).")
      .def(
          "indices",
          [](const Scene& s, size_t mesh) {
            const auto& i = mesh_at(s, mesh).indices;
            return copy_rows(i, py::ssize_t(i.size() / 3), 3);
          },
          py::arg("mesh") = 0, "A copy of a mesh's triangles, (M, 3) uint32.")
      .def(
          "material_ids",
          [](const Scene& s, size_t mesh) {
            const auto& i = mesh_at(s, mesh).material_ids;
            py::array_t<uint32_t> a(py::ssize_t(i.size()));
            if (!i.empty()) std::memcpy(a.mutable_data(), i.data(), i.size() * sizeof(uint32_t));
            return a;
          },
          py::arg("mesh") = 0, "A copy of a mesh's per-triangle material indices, (M,) uint32.")
      .def(
          "validation", [](const Scene& s) { return report_dict(validate_scene(s).report); },
          "Counts of valid, non-finite, bad-index and degenerate triangles.")
      .def(
          "bounds", [](const Scene& s) { return bounds_tuple(scene_bounds(s)); },
          "((lo x, y, z), (hi x, y, z)) of the finite vertices used by triangles.")
      .def("__repr__", [](const Scene& s) {
        return fmt::format("<kestrel.Scene '{}': {} meshes, {} triangles>", s.source,
                           s.meshes.size(), s.triangle_count());
      });

  m.def(
      "load_scene",
      [](const std::filesystem::path& path_) {
        const std::string path = path_.string();
        py::gil_scoped_release release;
        return std::make_shared<Scene>(load_scene(path));
      },
      py::arg("path"),
      "Loads an OBJ (+MTL), glTF/GLB file or builtin:NAME (OSError / ValueError naming the file).");
  m.def("builtin_scene_names", &builtin_scene_names);

  py::class_<Accel, std::shared_ptr<Accel>>(
      m, "Accel", "A scene ready to trace: a BVH over its valid triangles.")
      .def_property_readonly("layout",
                             [](const Accel& a) { return std::string(layout_name(a.layout)); })
      .def_readonly("prim_count", &Accel::prim_count)
      .def_property_readonly(
          "builder", [](const Accel& a) { return std::string(builder_name(a.builder)); },
          "The builder that made the tree (median when an SAH tree was too deep: depth_fallback).")
      .def_readonly("depth_fallback", &Accel::depth_fallback)
      .def_readonly("build_ms", &Accel::build_ms)
      .def_property_readonly("memory_bytes", &Accel::memory_bytes)
      .def_property_readonly("bytes_per_prim",
                             [](const Accel& a) {
                               return a.prim_count ? double(a.memory_bytes()) / double(a.prim_count)
                                                   : 0.0;
                             })
      .def_property_readonly("bounds", [](const Accel& a) { return bounds_tuple(a.bounds); })
      .def_property_readonly("validation",
                             [](const Accel& a) { return report_dict(a.validation.report); })
      .def("__repr__", [](const Accel& a) {
        return fmt::format("<kestrel.Accel {} over {} triangles, {:.1f} ms>", layout_name(a.layout),
                           a.prim_count, a.build_ms);
      });

  m.def(
      "build_accel",
      [](std::shared_ptr<Scene> scene, std::optional<std::string> builder,
         std::optional<std::string> quality, int threads, const std::string& layout,
         uint32_t max_leaf_size, float traversal_cost, float intersection_cost, uint32_t bins,
         uint32_t morton_bits, double expected_rays) {
        const BuildConfig config =
            build_config(builder, quality, layout, max_leaf_size, traversal_cost, intersection_cost,
                         bins, morton_bits, expected_rays);
        return without_gil(threads,
                           [&] { return std::make_shared<Accel>(build_accel(*scene, config)); });
      },
      py::arg("scene"), py::arg("builder") = py::none(), py::arg("quality") = py::none(),
      py::arg("threads") = 0, py::arg("layout") = "auto", py::arg("max_leaf_size") = 8,
      py::arg("traversal_cost") = 1.0f, py::arg("intersection_cost") = 1.0f, py::arg("bins") = 32,
      py::arg("morton_bits") = 30, py::arg("expected_rays") = 1e6,
      "Builds the BVH (builder None = by quality; quality None = balanced, i.e. binned SAH).");

  m.def(
      "bvh_metrics",
      [](std::shared_ptr<Scene> scene, std::optional<std::string> builder,
         std::optional<std::string> quality, int threads, uint32_t max_leaf_size,
         float traversal_cost, float intersection_cost, uint32_t bins, uint32_t morton_bits,
         double expected_rays) {
        const BuildConfig config =
            build_config(builder, quality, "bvh2", max_leaf_size, traversal_cost, intersection_cost,
                         bins, morton_bits, expected_rays);
        struct Out {
          SceneValidation validation;
          BvhMetrics metrics;
          std::string problem;
          double build_ms = 0;
          size_t refs = 0;
        };
        const Out o = without_gil(threads, [&] {
          Out r;
          r.validation = validate_scene(*scene);
          const Buffer<PrimRef> refs = make_prim_refs(*scene, r.validation);
          const Builder builder = resolve_builder(config, refs.size());
          const bool spatial = builder == Builder::spatial;
          const Buffer<Triangle> triangles = triangles_for_builder(*scene, r.validation, builder);
          Timer t;
          const Bvh2 bvh = build_bvh(refs, triangles, config);
          r.build_ms = t.ms();
          r.metrics = compute_metrics(bvh, config);
          r.problem = validate_bvh(bvh, refs, config.max_leaf_size, spatial);
          r.refs = refs.size();
          return r;
        });
        py::dict d;
        d["builder"] = builder_name(resolve_builder(config, o.refs));
        d["triangles"] = o.validation.report.triangle_count;
        d["valid_triangles"] = o.validation.report.valid_triangle_count;
        d["build_ms"] = o.build_ms;
        d["sah_cost"] = o.metrics.sah_cost;
        d["sah_cost_unit"] = o.metrics.sah_cost_unit;
        d["traversal_cost"] = config.traversal_cost;
        d["intersection_cost"] = config.intersection_cost;
        d["nodes"] = o.metrics.node_count;
        d["inner_nodes"] = o.metrics.inner_count;
        d["leaves"] = o.metrics.leaf_count;
        d["max_depth"] = o.metrics.max_depth;
        d["mean_leaf_depth"] = o.metrics.mean_leaf_depth;
        d["leaf_size_histogram"] = o.metrics.leaf_size_histogram;
        d["bytes_per_prim"] = o.metrics.bytes_per_prim;
        d["valid"] = o.problem.empty();
        d["problem"] = o.problem;
        return d;
      },
      py::arg("scene"), py::arg("builder") = py::none(), py::arg("quality") = py::none(),
      py::arg("threads") = 0, py::arg("max_leaf_size") = 8, py::arg("traversal_cost") = 1.0f,
      py::arg("intersection_cost") = 1.0f, py::arg("bins") = 32, py::arg("morton_bits") = 30,
      py::arg("expected_rays") = 1e6,
      "Builds the binary BVH and returns what `kestrel bvh --json` reports (SAH cost, counts, "
      "depth, ...).");

  m.def(
      "trace",
      [](std::shared_ptr<Accel> accel, py::handle rays, bool any_hit,
         std::optional<std::string> isa, std::optional<bool> packets, int threads, py::object out,
         std::optional<bool> stream) {
        return fields_of(
            ray_query<Hit>(rays, out, hit_dtype(), "kestrel.hit_dtype", isa, packets, threads,
                           [&](std::span<const Ray> r, std::span<Hit> hits, const TraceOptions& o) {
                             TraceOptions with = o;
                             with.stream = stream;
                             trace(*accel, r, hits, any_hit, with);
                           }));
      },
      py::arg("accel"), py::arg("rays"), py::arg("any_hit") = false, py::arg("isa") = py::none(),
      py::arg("packets") = py::none(), py::arg("threads") = 0, py::arg("out") = py::none(),
      py::arg("stream") = py::none(),
      "Closest (or any) hits of (N, 8) float32 rays (org, dir, tmin, tmax): a dict of t, prim_id, "
      "u, v "
      "(views of one record array of kestrel.hit_dtype, or of out=). A miss: t = inf, prim_id = "
      "invalid_id. stream=True traces the batch reordered by origin and direction (same hits, "
      "in the caller's order); None: kestrel's default (TraceOptions::stream).");

  m.def(
      "occluded",
      [](std::shared_ptr<Accel> accel, py::handle rays, std::optional<std::string> isa,
         std::optional<bool> packets, int threads, py::object out, std::optional<bool> stream) {
        return ray_query<uint8_t>(
            rays, out, py::dtype("?"), "bool", isa, packets, threads,
            [&](std::span<const Ray> r, std::span<uint8_t> flags, const TraceOptions& o) {
              TraceOptions with = o;
              with.stream = stream;
              occluded(*accel, r, flags, with);
            });
      },
      py::arg("accel"), py::arg("rays"), py::arg("isa") = py::none(),
      py::arg("packets") = py::none(), py::arg("threads") = 0, py::arg("out") = py::none(),
      py::arg("stream") = py::none(),
      "Whether each ray hits anything in (tmin, tmax): a bool array (N,) (or out=).");
}

}  // namespace kestrel::python
