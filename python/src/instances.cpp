// The InstancedScene binding: two-level scenes (meshes, instances, glTF animation, commit,
// trace / occluded over instance hits).
#include <fmt/format.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <cmath>

#include "queries.h"

namespace kestrel::python {

void bind_instances(py::module_& m) {
  py::class_<PyInstancedScene, std::shared_ptr<PyInstancedScene>>(
      m, "InstancedScene",
      "A two-level scene: meshes (one BVH each) placed by instances; commit() builds what changed.")
      .def(py::init([]() { return std::make_shared<PyInstancedScene>(); }))
      .def_static(
          "load_gltf",
          [](const std::filesystem::path& path_, size_t clip) {
            const std::string path = path_.string();
            auto s = std::make_shared<PyInstancedScene>();
            py::gil_scoped_release release;
            s->gltf.emplace(GltfInstances::load(path, clip));
            s->gltf->add_to(s->scene);
            s->scene.set_materials(s->gltf->materials(), s->gltf->textures());
            s->scene.set_source(path);
            return s;
          },
          py::arg("path"), py::arg("clip") = 0,
          "A glTF/GLB file as instances, posed at t = 0 (commit() before tracing).")
      .def(
          "add_mesh",
          [](PyInstancedScene& s, py::handle vertices, py::handle indices, const std::string& name,
             const std::string& nan_policy) {
            return s.scene.add_mesh(
                mesh_from_arrays(vertices, indices, py::none(), py::none(), name, nan_policy, 0));
          },
          py::arg("vertices"), py::arg("indices"), py::arg("name") = "mesh",
          py::arg("nan_policy") = "warn",
          "Adds a mesh in object space from (N, 3) float32 vertices and (M, 3) uint32 indices; "
          "returns its id.")
      .def(
          "add_scene_mesh",
          [](PyInstancedScene& s, const Scene& scene, size_t mesh) {
            return s.scene.add_mesh(mesh_at(scene, mesh));
          },
          py::arg("scene"), py::arg("mesh") = 0,
          "Adds a copy of one of a Scene's meshes; returns its id.")
      .def(
          "set_materials_from",
          [](PyInstancedScene& s, const Scene& scene) {
            s.scene.set_materials(scene.materials, scene.textures);
          },
          py::arg("scene"),
          "Takes a Scene's materials and textures (what meshes added with add_scene_mesh index); "
          "next commit().")
      .def(
          "add_instance",
          [](PyInstancedScene& s, MeshId mesh, py::handle transform, uint32_t mask) {
            const Affine3 t = transform.is_none() ? Affine3{} : affine_from(transform, "transform");
            return s.scene.add_instance(mesh, t, mask);
          },
          py::arg("mesh"), py::arg("transform") = py::none(), py::arg("mask") = 0xFFFFFFFFu,
          "Places a mesh with a (3, 4) or (4, 4) affine transform (None = identity); returns the "
          "instance id.")
      .def(
          "set_transform",
          [](PyInstancedScene& s, InstanceId id, py::handle transform) {
            s.scene.set_transform(id, affine_from(transform, "transform"));
          },
          py::arg("instance"), py::arg("transform"))
      .def(
          "set_mask",
          [](PyInstancedScene& s, InstanceId id, uint32_t mask) { s.scene.set_mask(id, mask); },
          py::arg("instance"), py::arg("mask"))
      .def(
          "update_vertices",
          [](PyInstancedScene& s, MeshId mesh, py::handle vertices) {
            auto v = input_array<float>(vertices, "vertices", {-1, 3});
            s.scene.update_vertices(mesh,
                                    {reinterpret_cast<const Vec3*>(v.data()), size_t(v.shape(0))});
          },
          py::arg("mesh"), py::arg("vertices"))
      .def("remove_instance",
           [](PyInstancedScene& s, InstanceId id) { s.scene.remove_instance(id); })
      .def("remove_mesh", [](PyInstancedScene& s, MeshId id) { s.scene.remove_mesh(id); })
      .def(
          "set_time",
          [](PyInstancedScene& s, double t) {
            if (!s.gltf)
              throw py::value_error("set_time: this scene was not loaded from a glTF file");
            if (!std::isfinite(t)) throw py::value_error("time: must be finite");
            s.gltf->set_time(s.scene, t);
          },
          py::arg("time"), "Poses a glTF scene at time t (seconds); commit() afterwards.")
      .def_property_readonly(
          "duration", [](const PyInstancedScene& s) { return s.gltf ? s.gltf->duration() : 0.0; })
      .def(
          "commit",
          [](PyInstancedScene& s, int threads) {
            return commit_dict(without_gil(threads, [&] { return s.scene.commit(); }));
          },
          py::arg("threads") = 0, "Builds what changed; returns the timings.")
      .def(
          "trace",
          [](const PyInstancedScene& s, py::handle rays, uint32_t ray_mask,
             std::optional<std::string> isa, std::optional<bool> packets, int threads,
             py::object out) {
            return fields_of(ray_query<InstanceHit>(
                rays, out, instance_hit_dtype(), "kestrel.instance_hit_dtype", isa, packets,
                threads,
                [&](std::span<const Ray> r, std::span<InstanceHit> hits, const TraceOptions& o) {
                  s.scene.trace(r, hits, ray_mask, o);
                }));
          },
          py::arg("rays"), py::arg("ray_mask") = 0xFFFFFFFFu, py::arg("isa") = py::none(),
          py::arg("packets") = py::none(), py::arg("threads") = 0, py::arg("out") = py::none(),
          "Closest hits: a dict of t, prim_id (in its mesh), instance_id, u, v.")
      .def(
          "occluded",
          [](const PyInstancedScene& s, py::handle rays, uint32_t ray_mask,
             std::optional<std::string> isa, std::optional<bool> packets, int threads,
             py::object out) {
            return ray_query<uint8_t>(
                rays, out, py::dtype("?"), "bool", isa, packets, threads,
                [&](std::span<const Ray> r, std::span<uint8_t> flags, const TraceOptions& o) {
                  s.scene.occluded(r, flags, ray_mask, o);
                });
          },
          py::arg("rays"), py::arg("ray_mask") = 0xFFFFFFFFu, py::arg("isa") = py::none(),
          py::arg("packets") = py::none(), py::arg("threads") = 0, py::arg("out") = py::none())
      .def(
          "transform",
          [](const PyInstancedScene& s, InstanceId id) {
            return affine_array(s.scene.transform(id));
          },
          py::arg("instance"), "The instance's transform, (3, 4) float32.")
      .def("instance_mesh",
           [](const PyInstancedScene& s, InstanceId id) { return s.scene.instance_mesh(id); })
      .def_property_readonly("instance_count",
                             [](const PyInstancedScene& s) { return s.scene.instance_count(); })
      .def_property_readonly("mesh_count",
                             [](const PyInstancedScene& s) { return s.scene.mesh_count(); })
      .def_property_readonly("memory_bytes",
                             [](const PyInstancedScene& s) { return s.scene.memory_bytes(); })
      .def(
          "flatten",
          [](const PyInstancedScene& s) { return std::make_shared<Scene>(s.scene.flatten()); },
          "The committed scene as one Scene: a mesh per instance, world-space vertices, "
          "instance-id order.");
}

}  // namespace kestrel::python
