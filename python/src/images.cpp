// Python bindings of kestrel's files: multi-layer EXR, PFM, PNG, any float image, the
// `.rays` / `.hits` interchange files, and the documented tone map.
#include <fmt/format.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <cstring>

#include "arrays.h"
#include "bindings.h"
#include "kestrel/io.h"
#include "kestrel/render.h"

namespace kestrel::python {

namespace {

std::vector<std::string> default_channel_names(const std::string& layer, int channels) {
  if (channels == 1) return {layer == "depth" ? "Z" : "Y"};
  if (channels == 2) return {"X", "Y"};
  if (channels == 3)
    return layer == "normal" ? std::vector<std::string>{"X", "Y", "Z"}
                             : std::vector<std::string>{"R", "G", "B"};
  if (channels == 4) return {"R", "G", "B", "A"};
  std::vector<std::string> n;
  for (int c = 0; c < channels; ++c) n.push_back(fmt::format("C{}", c));
  return n;
}

}  // namespace

void bind_images(py::module_& m) {
  m.def(
      "read_exr",
      [](const std::filesystem::path& path_) {
        const std::string path = path_.string();
        std::vector<ImageLayer> layers;
        {
          py::gil_scoped_release release;
          layers = read_exr(path);
        }
        py::dict d;
        for (ImageLayer& l : layers) d[py::str(l.name)] = take_image(std::move(l.image));
        return d;
      },
      py::arg("path"),
      "Every layer of an EXR as float32 (H, W, C) arrays, by layer name (bare R, G, B: 'color').");
  m.def(
      "write_exr",
      [](const std::filesystem::path& path_, py::dict layers,
         std::optional<std::map<std::string, std::vector<std::string>>> channels) {
        const std::string path = path_.string();
        std::vector<ImageLayer> out;
        for (auto [key, value] : layers) {
          const std::string name = py::str(key);
          const std::string arg = fmt::format("layers['{}']", name);
          ImageLayer l;
          l.name = name;
          l.image = image_from_array(value, arg.c_str());
          if (channels && channels->count(name)) {
            l.channel_names = channels->at(name);
            if (int(l.channel_names.size()) != l.image.channels)
              throw py::value_error(fmt::format("channels['{}']: {} names for {} channels", name,
                                                l.channel_names.size(), l.image.channels));
          } else {
            l.channel_names = default_channel_names(name, l.image.channels);
          }
          if (!out.empty() &&
              (l.image.width != out[0].image.width || l.image.height != out[0].image.height))
            throw py::value_error(fmt::format("{}: size {}x{} differs from layer '{}' ({}x{})", arg,
                                              l.image.width, l.image.height, out[0].name,
                                              out[0].image.width, out[0].image.height));
          out.push_back(std::move(l));
        }
        if (out.empty()) throw py::value_error("layers: no layer to write");
        py::gil_scoped_release release;
        write_exr(path, out);
      },
      py::arg("path"), py::arg("layers"), py::arg("channels") = py::none(),
      "Writes {layer: (H, W, C) float32} as one EXR ('color' or '' as bare R, G, B).");
  m.def(
      "read_pfm",
      [](const std::filesystem::path& path_) {
        const std::string path = path_.string();
        FloatImage image;
        {
          py::gil_scoped_release release;
          image = read_pfm(path);
        }
        return take_image(std::move(image));
      },
      py::arg("path"), "A PFM as float32 (H, W, 1|3), rows top to bottom.");
  m.def(
      "write_pfm",
      [](const std::filesystem::path& path_, py::handle image) {
        const std::string path = path_.string();
        const FloatImage img = image_from_array(image, "image");
        if (img.channels < 1 || img.channels > 3)
          throw py::value_error(
              fmt::format("image: PFM holds 1 to 3 channels, got {}", img.channels));
        py::gil_scoped_release release;
        write_pfm(path, img);
      },
      py::arg("path"), py::arg("image"),
      "Writes (H, W, 1|2|3) float32 as PFM (2 channels padded with zeros).");
  m.def(
      "read_image",
      [](const std::filesystem::path& path_) {
        const std::string path = path_.string();
        FloatImage image;
        {
          py::gil_scoped_release release;
          image = read_float_image(path);
        }
        return take_image(std::move(image));
      },
      py::arg("path"),
      "Any float image kestrel reads (.pfm, .exr, .hdr, 8-bit sRGB-decoded PNG/JPEG).");
  m.def(
      "write_png",
      [](const std::filesystem::path& path_, py::handle rgb) {
        const std::string path = path_.string();
        auto a = input_array<uint8_t>(rgb, "rgb", {-1, -1, 3});
        py::gil_scoped_release release;
        write_png(path, int(a.shape(1)), int(a.shape(0)), {a.data(), size_t(a.size())});
      },
      py::arg("path"), py::arg("rgb"), "Writes uint8 (H, W, 3) as PNG.");
  m.def(
      "tonemap",
      [](py::handle color, float exposure) {
        const FloatImage img = image_from_array(color, "color", 3);
        std::vector<uint8_t> rgb = tonemap_srgb8(img, exposure);
        return take_vector(std::move(rgb), {img.height, img.width, 3});
      },
      py::arg("color"), py::arg("exposure") = 0.0f,
      "The documented tone map (2^exposure, ACES fit, sRGB) of (H, W, 3) float32 into uint8 (H, W, "
      "3).");

  m.def(
      "read_rays",
      [](const std::filesystem::path& path_) {
        const std::string path = path_.string();
        std::vector<Ray> rays;
        {
          py::gil_scoped_release release;
          rays = read_rays(path);
        }
        py::array_t<float> a({py::ssize_t(rays.size()), py::ssize_t(8)});
        if (!rays.empty()) std::memcpy(a.mutable_data(), rays.data(), rays.size() * sizeof(Ray));
        return a;
      },
      py::arg("path"), "A `.rays` file as (N, 8) float32.");
  m.def(
      "write_rays",
      [](const std::filesystem::path& path_, py::handle rays) {
        const std::string path = path_.string();
        auto r = input_array<float>(rays, "rays", {-1, 8});
        py::gil_scoped_release release;
        write_rays(path, {reinterpret_cast<const Ray*>(r.data()), size_t(r.shape(0))});
      },
      py::arg("path"), py::arg("rays"));
  m.def(
      "read_hits",
      [](const std::filesystem::path& path_) {
        const std::string path = path_.string();
        std::vector<Hit> hits;
        {
          py::gil_scoped_release release;
          hits = read_hits(path);
        }
        py::array_t<float> t(py::ssize_t(hits.size()));
        py::array_t<uint32_t> id(py::ssize_t(hits.size()));
        for (size_t i = 0; i < hits.size(); ++i) {
          t.mutable_data()[i] = hits[i].t;
          id.mutable_data()[i] = hits[i].prim_id;
        }
        py::dict d;
        d["t"] = t;
        d["prim_id"] = id;
        return d;
      },
      py::arg("path"), "A `.hits` file as a dict of t (float32) and prim_id (uint32).");
  m.def(
      "write_hits",
      [](const std::filesystem::path& path_, py::handle t, py::handle prim_id) {
        const std::string path = path_.string();
        auto ts = input_array<float>(t, "t", {-1});
        auto ids = input_array<uint32_t>(prim_id, "prim_id", {ts.shape(0)});
        std::vector<Hit> hits(size_t(ts.shape(0)));
        for (size_t i = 0; i < hits.size(); ++i) {
          hits[i].t = ts.data()[i];
          hits[i].prim_id = ids.data()[i];
        }
        py::gil_scoped_release release;
        write_hits(path, hits);
      },
      py::arg("path"), py::arg("t"), py::arg("prim_id"));
}

}  // namespace kestrel::python
