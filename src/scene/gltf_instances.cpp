// glTF 2.0 as a two-level scene: meshes once, nodes as instances, animations sampled per
// frame (node TRS channels and morph-target weights).
#include <algorithm>
#include <array>
#include <cmath>
#include <map>

#include "io/gltf_reader.h"
#include "kestrel/error.h"
#include "kestrel/instances.h"

namespace kestrel {

namespace {

using gltf::Mat4;

// A vertex's four joints and weights (JOINTS_0, WEIGHTS_0), the weights normalised to sum 1
// (all 0: the vertex is not moved by the skin).
struct SkinVertex {
  std::array<uint32_t, 4> joint{};
  std::array<float, 4> weight{};
};

struct MorphMesh {
  TriangleMesh base;
  std::vector<std::vector<Vec3>> targets;  // per target: one delta per base position
  std::vector<float> weights;              // default weights
  std::vector<SkinVertex> skin;            // one per base position, or empty
};

struct Skin {
  std::vector<int> joints;         // nodes
  std::vector<Mat4> inverse_bind;  // one per joint
};

struct Node {
  double t[3] = {0, 0, 0}, r[4] = {0, 0, 0, 1}, s[3] = {1, 1, 1};
  bool has_matrix = false;
  Mat4 matrix{};
  int mesh = -1, skin = -1;
  std::vector<int> children;
  std::vector<float> weights;
};

enum class Path { translation, rotation, scale, weights };

struct Channel {
  int node;
  Path path;
  std::vector<float> times, values;
  int components;  // per keyframe value (weights: the target count)
  bool step = false, cubic = false;
};

Mat4 trs_matrix(const Node& n) {
  if (n.has_matrix) return n.matrix;
  const double x = n.r[0], y = n.r[1], z = n.r[2], w = n.r[3];
  Mat4 m{};
  m[0] = (1 - 2 * (y * y + z * z)) * n.s[0];
  m[1] = (2 * (x * y + z * w)) * n.s[0];
  m[2] = (2 * (x * z - y * w)) * n.s[0];
  m[4] = (2 * (x * y - z * w)) * n.s[1];
  m[5] = (1 - 2 * (x * x + z * z)) * n.s[1];
  m[6] = (2 * (y * z + x * w)) * n.s[1];
  m[8] = (2 * (x * z + y * w)) * n.s[2];
  m[9] = (2 * (y * z - x * w)) * n.s[2];
  m[10] = (1 - 2 * (x * x + y * y)) * n.s[2];
  m[12] = n.t[0], m[13] = n.t[1], m[14] = n.t[2], m[15] = 1;
  return m;
}

Affine3 to_affine(const Mat4& m) {  // column-major 4x4 -> row-major 3x4
  Affine3 a;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) a.m[4 * r + c] = float(m[c * 4 + r]);
  return a;
}

// Value of a channel at time t: keyframe interval by binary search, then LINEAR (slerp for
// rotations), STEP, or CUBICSPLINE: the glTF 2.0 cubic Hermite spline through the values
// with each key's in- and out-tangents (scaled by the interval), rotations renormalised.
void sample(const Channel& ch, double t, double* out) {
  const size_t n = ch.times.size();
  const int c = ch.components;
  auto value = [&](size_t k, int i) {
    return double(ch.values[(ch.cubic ? 3 * k + 1 : k) * size_t(c) + size_t(i)]);
  };
  if (t <= ch.times[0] || n == 1) {
    for (int i = 0; i < c; ++i) out[i] = value(0, i);
    return;
  }
  if (t >= ch.times[n - 1]) {
    for (int i = 0; i < c; ++i) out[i] = value(n - 1, i);
    return;
  }
  const size_t k =
      size_t(std::upper_bound(ch.times.begin(), ch.times.end(), float(t)) - ch.times.begin()) - 1;
  const double t0 = ch.times[k], t1 = ch.times[k + 1];
  const double u = ch.step || t1 <= t0 ? 0.0 : (t - t0) / (t1 - t0);
  if (ch.cubic && !ch.step) {
    // Keys are stored (in-tangent a, value v, out-tangent b): p = h00 v_k + h10 dt b_k +
    // h01 v_k+1 + h11 dt a_k+1 (glTF 2.0, Appendix C).
    const double dt = t1 - t0, u2 = u * u, u3 = u2 * u;
    const double h00 = 2 * u3 - 3 * u2 + 1, h10 = u3 - 2 * u2 + u, h01 = -2 * u3 + 3 * u2,
                 h11 = u3 - u2;
    auto at = [&](size_t key, int part, int i) {
      return double(ch.values[(3 * key + size_t(part)) * size_t(c) + size_t(i)]);
    };
    double len = 0;
    for (int i = 0; i < c; ++i) {
      out[i] = h00 * at(k, 1, i) + h10 * dt * at(k, 2, i) + h01 * at(k + 1, 1, i) +
               h11 * dt * at(k + 1, 0, i);
      len += out[i] * out[i];
    }
    if (ch.path == Path::rotation && len > 0)
      for (int i = 0; i < 4; ++i) out[i] /= std::sqrt(len);
    return;
  }
  if (ch.path == Path::rotation && !ch.step) {
    double a[4], b[4];
    for (int i = 0; i < 4; ++i) a[i] = value(k, i), b[i] = value(k + 1, i);
    double d = a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3];
    if (d < 0) {
      d = -d;
      for (double& x : b) x = -x;
    }
    double wa = 1 - u, wb = u;
    if (d < 0.9995) {
      const double th = std::acos(d), sn = std::sin(th);
      wa = std::sin((1 - u) * th) / sn;
      wb = std::sin(u * th) / sn;
    }
    double len = 0;
    for (int i = 0; i < 4; ++i) out[i] = wa * a[i] + wb * b[i], len += out[i] * out[i];
    len = std::sqrt(len);
    if (len > 0)
      for (int i = 0; i < 4; ++i) out[i] /= len;
    return;
  }
  for (int i = 0; i < c; ++i) out[i] = (1 - u) * value(k, i) + u * value(k + 1, i);
}

}  // namespace

// A primitive's JOINTS_0 and WEIGHTS_0 (bytes or shorts; floats or normalised bytes or
// shorts), or none when it lacks either. Weights that are negative or not finite are an error
// naming the mesh.
std::vector<SkinVertex> read_skin_vertices(const gltf::GltfReader& reader,
                                           const tinygltf::Primitive& prim, size_t count,
                                           const std::string& mesh) {
  const auto j = prim.attributes.find("JOINTS_0"), w = prim.attributes.find("WEIGHTS_0");
  if (j == prim.attributes.end() || w == prim.attributes.end()) return {};
  const std::vector<float> joints = reader.read_floats(j->second, 4),
                           weights = reader.read_floats(w->second, 4);
  if (joints.size() != 4 * count || weights.size() != 4 * count)
    reader.fail(
        fmt::format("mesh '{}': JOINTS_0 / WEIGHTS_0 do not have one entry per vertex", mesh));
  std::vector<SkinVertex> out(count);
  for (size_t i = 0; i < count; ++i) {
    float sum = 0;
    for (size_t k = 0; k < 4; ++k) {
      const float x = weights[4 * i + k];
      if (!(x >= 0) || !std::isfinite(x))
        reader.fail(fmt::format("mesh '{}': vertex {} has skin weight {}", mesh, i, x));
      out[i].joint[k] = uint32_t(joints[4 * i + k]);
      out[i].weight[k] = x;
      sum += x;
    }
    for (float& x : out[i].weight) x = sum > 0 ? x / sum : 0.0f;
  }
  return out;
}

// Linear blend skinning: each vertex moved by its joints' world matrices times their inverse
// bind matrices, weighted (joints outside the skin are left out); normals by the blended 3x3,
// renormalised. Vertices without weights stay where they are.
void skin_vertices(const Skin& sk, const std::vector<Mat4>& world, const MorphMesh& mm,
                   std::vector<Vec3>& p, std::vector<Vec3>& n) {
  std::vector<Mat4> jm(sk.joints.size());
  for (size_t j = 0; j < jm.size(); ++j)
    jm[j] = gltf::mul(world[size_t(sk.joints[j])], sk.inverse_bind[j]);
  const bool normals = mm.base.normals.size() == p.size();
  if (normals) n = mm.base.normals;
  for (size_t i = 0; i < p.size() && i < mm.skin.size(); ++i) {
    const SkinVertex& v = mm.skin[i];
    Mat4 m{};
    double total = 0;
    for (size_t k = 0; k < 4; ++k) {
      if (!(v.weight[k] > 0) || v.joint[k] >= jm.size()) continue;
      for (size_t e = 0; e < 16; ++e) m[e] += v.weight[k] * jm[v.joint[k]][e];
      total += v.weight[k];
    }
    if (!(total > 0)) continue;
    m[15] = 1;
    p[i] = gltf::transform_point(m, p[i]);
    if (normals) {
      const Vec3 a = n[i];
      const Vec3 b{float(m[0] * a.x + m[4] * a.y + m[8] * a.z),
                   float(m[1] * a.x + m[5] * a.y + m[9] * a.z),
                   float(m[2] * a.x + m[6] * a.y + m[10] * a.z)};
      const float len = length(b);
      n[i] = len > 0 && std::isfinite(len) ? b * (1.0f / len) : a;
    }
  }
}

struct GltfInstances::Impl {
  std::string path;
  std::vector<MorphMesh> meshes;
  std::vector<Skin> skins;
  std::vector<Node> nodes;
  std::vector<int> roots;
  std::vector<Channel> channels;
  std::vector<Material> materials;
  std::vector<Texture> textures;
  std::vector<std::pair<int, Light>> node_lights;  // (node, light in the node's space)
  std::vector<Light> lights;                       // posed (world space)
  double duration = 0;
  // Filled by add_to().
  std::vector<MeshId> mesh_ids;
  std::vector<std::pair<int, InstanceId>> node_instances;  // (node, instance)
  std::vector<std::vector<float>> posed_weights;           // per mesh, last weights applied
  std::vector<uint8_t> hidden;                             // per node_instances entry
  bool added = false;

  // Lights placed by their nodes' world matrices; a node scaled to nothing turns its light off.
  void pose_lights(const std::vector<Mat4>& world) {
    lights.clear();
    for (const auto& [node, local] : node_lights) {
      Light l = local;
      if (!gltf::place_light(l, world[size_t(node)])) l.intensity = 0;
      lights.push_back(l);
    }
  }

  std::vector<Mat4> world_matrices(const std::vector<Node>& posed) const {
    std::vector<Mat4> world(posed.size(), gltf::identity());
    auto visit = [&](auto&& self, int n, const Mat4& parent, int depth) -> void {
      if (depth > 256)
        throw Error(ErrorCode::parse_error,
                    fmt::format("{}: node {}: hierarchy deeper than 256 (cycle?)", path, n));
      world[size_t(n)] = gltf::mul(parent, trs_matrix(posed[size_t(n)]));
      for (int c : posed[size_t(n)].children) self(self, c, world[size_t(n)], depth + 1);
    };
    for (int r : roots) visit(visit, r, gltf::identity(), 0);
    return world;
  }
};

GltfInstances::GltfInstances() : impl_(new Impl) {}
GltfInstances::~GltfInstances() = default;
GltfInstances::GltfInstances(GltfInstances&&) noexcept = default;
GltfInstances& GltfInstances::operator=(GltfInstances&&) noexcept = default;

GltfInstances GltfInstances::load(const std::string& path, size_t clip) {
  const tinygltf::Model model = gltf::load_model(path);
  const gltf::GltfReader reader{path, model};
  GltfInstances out;
  Impl& g = *out.impl_;
  g.path = path;
  for (const auto& m : model.materials) g.materials.push_back(gltf::convert_material(m, model));
  for (const auto& t : model.textures) g.textures.push_back(gltf::convert_texture(t, model));
  const uint32_t default_material = uint32_t(g.materials.size());
  g.materials.push_back(Material{.name = "default"});
  for (const tinygltf::Mesh& gm : model.meshes) {
    MorphMesh mm;
    mm.base.name = gm.name;
    size_t target_count = 0;
    for (const tinygltf::Primitive& p : gm.primitives)
      target_count = std::max(target_count, p.targets.size());
    mm.targets.resize(target_count);
    bool all_normals = true;
    for (const tinygltf::Primitive& prim : gm.primitives) {
      std::vector<Vec3> positions;
      std::vector<uint32_t> indices;
      if (!reader.read_triangles(prim, positions, indices)) continue;
      std::vector<Vec3> normals;
      std::vector<Vec2> uvs;
      reader.read_normals_uvs(prim, positions.size(), normals, uvs);
      all_normals &= normals.size() == positions.size();
      if (all_normals)
        mm.base.normals.insert(mm.base.normals.end(), normals.begin(), normals.end());
      gltf::add_per_vertex(mm.base.uvs, mm.base.positions.size(), uvs, positions.size(),
                           Vec2{0, 0});
      gltf::add_per_vertex(mm.skin, mm.base.positions.size(),
                           read_skin_vertices(reader, prim, positions.size(), gm.name),
                           positions.size(), SkinVertex{});
      gltf::add_per_vertex(mm.base.colors, mm.base.positions.size(),
                           reader.read_colors(prim, positions.size()), positions.size(),
                           Vec3{1, 1, 1});
      const uint32_t material = prim.material >= 0 && size_t(prim.material) < model.materials.size()
                                    ? uint32_t(prim.material)
                                    : default_material;
      const uint32_t base = uint32_t(mm.base.positions.size());
      mm.base.positions.insert(mm.base.positions.end(), positions.begin(), positions.end());
      for (size_t i = 0; i + 2 < indices.size(); i += 3) {
        for (int k = 0; k < 3; ++k)
          mm.base.indices.push_back(indices[i + k] < positions.size() ? base + indices[i + k]
                                                                      : 0xFFFFFFFFu);
        mm.base.material_ids.push_back(material);
      }
      for (size_t k = 0; k < target_count; ++k) {
        std::vector<Vec3> delta(positions.size(), Vec3{0, 0, 0});
        if (k < prim.targets.size()) {
          if (auto it = prim.targets[k].find("POSITION"); it != prim.targets[k].end()) {
            delta = reader.read_vec3(it->second);
            if (delta.size() != positions.size())
              reader.fail(fmt::format("mesh '{}': morph target {} has {} positions for {} vertices",
                                      gm.name, k, delta.size(), positions.size()));
          }
        }
        mm.targets[k].insert(mm.targets[k].end(), delta.begin(), delta.end());
      }
    }
    if (!all_normals) mm.base.normals.clear();
    mm.weights.assign(target_count, 0.0f);
    for (size_t k = 0; k < std::min(target_count, gm.weights.size()); ++k)
      mm.weights[k] = float(gm.weights[k]);
    g.meshes.push_back(std::move(mm));
  }
  for (const tinygltf::Skin& s : model.skins) {
    Skin skin;
    for (int j : s.joints) {
      if (j < 0 || size_t(j) >= model.nodes.size())
        reader.fail(fmt::format("skin '{}' names missing joint node {}", s.name, j));
      skin.joints.push_back(j);
    }
    skin.inverse_bind.assign(skin.joints.size(), gltf::identity());
    if (s.inverseBindMatrices >= 0) {
      const std::vector<float> m = reader.read_floats(s.inverseBindMatrices, 16);
      if (m.size() < 16 * skin.joints.size())
        reader.fail(fmt::format("skin '{}': {} inverse bind matrices for {} joints", s.name,
                                m.size() / 16, skin.joints.size()));
      for (size_t j = 0; j < skin.joints.size(); ++j)
        for (size_t k = 0; k < 16; ++k) skin.inverse_bind[j][k] = m[16 * j + k];
    }
    g.skins.push_back(std::move(skin));
  }
  for (size_t i = 0; i < model.nodes.size(); ++i) {
    const tinygltf::Node& n = model.nodes[i];
    Node node;
    if (n.matrix.size() == 16) {
      node.has_matrix = true;
      for (int k = 0; k < 16; ++k) node.matrix[size_t(k)] = n.matrix[size_t(k)];
    }
    if (n.translation.size() == 3) std::copy(n.translation.begin(), n.translation.end(), node.t);
    if (n.rotation.size() == 4) std::copy(n.rotation.begin(), n.rotation.end(), node.r);
    if (n.scale.size() == 3) std::copy(n.scale.begin(), n.scale.end(), node.s);
    if (n.mesh >= 0 && size_t(n.mesh) >= model.meshes.size())
      reader.fail(fmt::format("node {} names missing mesh {}", i, n.mesh));
    node.mesh = n.mesh;
    if (n.skin >= 0 && size_t(n.skin) >= model.skins.size())
      reader.fail(fmt::format("node {} names missing skin {}", i, n.skin));
    node.skin = n.mesh >= 0 && !g.meshes[size_t(n.mesh)].skin.empty() ? n.skin : -1;
    for (int c : n.children) {
      if (c < 0 || size_t(c) >= model.nodes.size())
        reader.fail(fmt::format("node {} names missing child {}", i, c));
      node.children.push_back(c);
    }
    if (node.mesh >= 0) {
      node.weights = g.meshes[size_t(node.mesh)].weights;
      for (size_t k = 0; k < std::min(node.weights.size(), n.weights.size()); ++k)
        node.weights[k] = float(n.weights[k]);
    }
    g.nodes.push_back(std::move(node));
  }
  const int scene_index = model.defaultScene >= 0 ? model.defaultScene : 0;
  if (size_t(scene_index) < model.scenes.size()) {
    for (int r : model.scenes[size_t(scene_index)].nodes) {
      if (r < 0 || size_t(r) >= model.nodes.size())
        reader.fail(fmt::format("scene names missing node {}", r));
      g.roots.push_back(r);
    }
  } else {
    for (size_t i = 0; i < model.nodes.size(); ++i) g.roots.push_back(int(i));
  }
  if (!model.animations.empty() && clip >= model.animations.size())
    reader.fail(fmt::format("no animation clip {} ({} clips)", clip, model.animations.size()));
  for (size_t a = 0; a < model.animations.size(); ++a) {
    if (a != clip) continue;  // clips may drive the same targets: one at a time
    const tinygltf::Animation& anim = model.animations[a];
    for (const tinygltf::AnimationChannel& c : anim.channels) {
      if (c.target_node < 0 || size_t(c.target_node) >= model.nodes.size())
        continue;  // glTF allows untargeted channels
      if (c.sampler < 0 || size_t(c.sampler) >= anim.samplers.size())
        reader.fail(
            fmt::format("animation '{}': channel names missing sampler {}", anim.name, c.sampler));
      const tinygltf::AnimationSampler& s = anim.samplers[size_t(c.sampler)];
      Channel ch;
      ch.node = c.target_node;
      if (c.target_path == "translation")
        ch.path = Path::translation, ch.components = 3;
      else if (c.target_path == "rotation")
        ch.path = Path::rotation, ch.components = 4;
      else if (c.target_path == "scale")
        ch.path = Path::scale, ch.components = 3;
      else if (c.target_path == "weights") {
        const int mesh = g.nodes[size_t(c.target_node)].mesh;
        if (mesh < 0) continue;
        ch.path = Path::weights;
        ch.components = int(g.meshes[size_t(mesh)].targets.size());
        if (ch.components == 0) continue;
      } else {
        continue;  // pointer / unknown paths
      }
      ch.times = reader.read_floats(s.input, 1);
      ch.step = s.interpolation == "STEP";
      ch.cubic = s.interpolation == "CUBICSPLINE";
      // Weights are SCALAR accessors of count keyframes x targets; the others VEC3 / VEC4.
      ch.values = ch.path == Path::weights ? reader.read_floats(s.output, 1)
                                           : reader.read_floats(s.output, ch.components);
      const size_t per_key = size_t(ch.components) * (ch.cubic ? 3 : 1);
      if (ch.times.empty() || ch.values.size() != ch.times.size() * per_key)
        reader.fail(fmt::format("animation '{}': sampler {} has {} keyframes but {} values",
                                anim.name, c.sampler, ch.times.size(), ch.values.size()));
      for (size_t k = 0; k < ch.times.size(); ++k)
        if (!std::isfinite(ch.times[k]) || (k > 0 && ch.times[k] < ch.times[k - 1]))
          reader.fail(fmt::format("animation '{}': sampler {} keyframe times are not increasing",
                                  anim.name, c.sampler));
      for (float v : ch.values)
        if (!std::isfinite(v))
          reader.fail(
              fmt::format("animation '{}': sampler {} has a NaN/Inf value", anim.name, c.sampler));
      g.duration = std::max(g.duration, double(ch.times.back()));
      g.channels.push_back(std::move(ch));
    }
  }
  // Instances: every node with a mesh reachable from the scene's roots.
  std::vector<uint8_t> reachable(g.nodes.size(), 0);
  auto mark = [&](auto&& self, int n, int depth) -> void {
    if (depth > 256) reader.fail(fmt::format("node {}: hierarchy deeper than 256 (cycle?)", n));
    reachable[size_t(n)] = 1;
    for (int c : g.nodes[size_t(n)].children) self(self, c, depth + 1);
  };
  for (int r : g.roots) mark(mark, r, 0);
  for (size_t i = 0; i < g.nodes.size(); ++i)
    if (reachable[i] && g.nodes[i].mesh >= 0) g.node_instances.push_back({int(i), 0});
  for (size_t i = 0; i < g.nodes.size(); ++i)
    if (reachable[i])
      if (auto l = gltf::node_light(path, model, int(i), gltf::identity()))
        g.node_lights.push_back({int(i), *l});
  g.pose_lights(g.world_matrices(g.nodes));
  return out;
}

size_t GltfInstances::mesh_count() const {
  return impl_->meshes.size();
}
const std::vector<Material>& GltfInstances::materials() const {
  return impl_->materials;
}
const std::vector<Texture>& GltfInstances::textures() const {
  return impl_->textures;
}
const std::vector<Light>& GltfInstances::lights() const {
  return impl_->lights;
}
size_t GltfInstances::instance_count() const {
  return impl_->node_instances.size();
}
double GltfInstances::duration() const {
  return impl_->duration;
}

void GltfInstances::add_to(InstancedScene& scene) {
  Impl& g = *impl_;
  if (g.added)
    throw Error(ErrorCode::invalid_argument, fmt::format("{}: already added to a scene", g.path));
  for (const MorphMesh& m : g.meshes) g.mesh_ids.push_back(scene.add_mesh(m.base));
  g.posed_weights.assign(g.meshes.size(), {});
  const std::vector<Mat4> world = g.world_matrices(g.nodes);
  g.hidden.assign(g.node_instances.size(), 0);
  for (size_t k = 0; k < g.node_instances.size(); ++k) {
    auto& [node, id] = g.node_instances[k];
    // A skinned mesh's vertices are placed by its joints alone (glTF): its node's own
    // transform is not used.
    Affine3 a = g.nodes[size_t(node)].skin >= 0 ? Affine3{} : to_affine(world[size_t(node)]);
    const bool singular = !transform_problem(a).empty();
    if (singular) a = Affine3{};
    id = scene.add_instance(g.mesh_ids[size_t(g.nodes[size_t(node)].mesh)], a,
                            singular ? 0u : 0xFFFFFFFFu);
    g.hidden[k] = singular;
  }
  g.added = true;
  set_time(scene, 0.0);
}

void GltfInstances::set_time(InstancedScene& scene, double t) {
  Impl& g = *impl_;
  if (!g.added)
    throw Error(ErrorCode::invalid_argument, fmt::format("{}: set_time before add_to", g.path));
  if (g.duration > 0 && std::isfinite(t)) t = std::fmod(std::max(0.0, t), g.duration);
  std::vector<Node> posed = g.nodes;
  for (const Channel& ch : g.channels) {
    Node& n = posed[size_t(ch.node)];
    double v[64];
    if (ch.components > 64) continue;
    sample(ch, t, v);
    switch (ch.path) {
      case Path::translation:
        std::copy(v, v + 3, n.t), n.has_matrix = false;
        break;
      case Path::rotation:
        std::copy(v, v + 4, n.r), n.has_matrix = false;
        break;
      case Path::scale:
        std::copy(v, v + 3, n.s), n.has_matrix = false;
        break;
      case Path::weights:
        for (int k = 0; k < ch.components; ++k) n.weights[size_t(k)] = float(v[k]);
        break;
    }
  }
  const std::vector<Mat4> world = g.world_matrices(posed);
  g.pose_lights(world);
  for (size_t k = 0; k < g.node_instances.size(); ++k) {
    const auto [node, id] = g.node_instances[k];
    const Node& pn = posed[size_t(node)];
    const Affine3 a = pn.skin >= 0 ? Affine3{} : to_affine(world[size_t(node)]);
    const bool singular = !transform_problem(a).empty();
    if (singular) {
      if (!g.hidden[k]) scene.set_mask(id, 0), g.hidden[k] = 1;
      continue;
    }
    scene.set_transform(id, a);
    if (g.hidden[k]) scene.set_mask(id, 0xFFFFFFFFu), g.hidden[k] = 0;
    // Morph targets, then the skin: the mesh follows its (first) node's weights and joints.
    const int mesh = pn.mesh;
    const MorphMesh& mm = g.meshes[size_t(mesh)];
    const bool skinned = pn.skin >= 0;
    if (!skinned && (mm.targets.empty() || pn.weights == g.posed_weights[size_t(mesh)])) continue;
    std::vector<Vec3> p = mm.base.positions, n;
    const std::vector<float>& w = pn.weights;
    for (size_t j = 0; j < mm.targets.size(); ++j) {
      if (w[j] == 0.0f) continue;
      for (size_t i = 0; i < p.size(); ++i)
        p[i] = {p[i].x + w[j] * mm.targets[j][i].x, p[i].y + w[j] * mm.targets[j][i].y,
                p[i].z + w[j] * mm.targets[j][i].z};
    }
    if (skinned) skin_vertices(g.skins[size_t(pn.skin)], world, mm, p, n);
    scene.update_vertices(g.mesh_ids[size_t(mesh)], p, n);
    g.posed_weights[size_t(mesh)] = w;
  }
}

}  // namespace kestrel
