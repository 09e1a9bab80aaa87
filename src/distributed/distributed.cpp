// Distributed rendering over MPI: dynamic tiles, rank 0 the queue (see distributed.h).
//
// Protocol (MPI_COMM_WORLD, point to point):
//   worker -> 0  tag_request  int32 want                first ask, with how many tiles it takes
//   0 -> worker  tag_work     uint32 tiles[k]           k = 0: the frame is done
//   worker -> 0  tag_result   float pixels[...]          the tiles it was given, in order; asks
//   again
// The result of tile list L is, tile by tile, AOV by AOV, the tile's pixels row by row with
// their channels: both sides compute the layout from the list and the frame size, so nothing
// else crosses. At the end MPI_Gather brings every rank's RankStats to rank 0.
//
// Rank 0 answers from a service thread that polls (MPI_Iprobe + a short sleep: OpenMPI's
// blocking calls spin, which would take a core from rendering) while its main thread renders
// chunks from the same queue; only the service thread calls MPI during the frame
// (MPI_THREAD_SERIALIZED).
#include "distributed/distributed.h"

#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <mutex>
#include <thread>

#include "core/timer.h"
#include "kestrel/error.h"
#include "kestrel/parallel.h"

#ifdef KESTREL_HAVE_MPI
#include <mpi.h>
#endif

namespace kestrel::distributed {

namespace {

int world_rank = 0, world_size = 1;
bool started = false;

[[maybe_unused]] constexpr int tag_request = 1, tag_work = 2, tag_result = 3;

// Launched by mpirun (OpenMPI, or a PMI-based launcher such as MPICH's Hydra or Slurm's).
bool launched_by_mpirun() {
  for (const char* v : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK"})
    if (std::getenv(v)) return true;
  return false;
}

// The pixels of tile t: calls f(pixel index) row by row.
template <class F>
void tile_pixels(uint32_t t, int width, int height, F&& f) {
  const int s = render_tile_size(), tiles_x = (width + s - 1) / s;
  const int x0 = int(t % uint32_t(tiles_x)) * s, y0 = int(t / uint32_t(tiles_x)) * s;
  for (int y = y0; y < std::min(y0 + s, height); ++y)
    for (int x = x0; x < std::min(x0 + s, width); ++x) f(size_t(y) * size_t(width) + size_t(x));
}

[[maybe_unused]] void pack(const Frame& f, const std::vector<uint32_t>& tiles,
                           std::vector<float>& out) {
  out.clear();
  for (uint32_t t : tiles)
    for (int a = 0; a < aov_count; ++a) {
      const FloatImage& img = f.aov[a];
      const size_t c = size_t(img.channels);
      tile_pixels(t, f.width, f.height, [&](size_t p) {
        out.insert(out.end(), &img.pixels[p * c], &img.pixels[p * c] + c);
      });
    }
}

[[maybe_unused]] size_t packed_size(const std::vector<uint32_t>& tiles, int width, int height) {
  size_t pixels = 0, channels = 0;
  for (uint32_t t : tiles) tile_pixels(t, width, height, [&](size_t) { ++pixels; });
  for (int a = 0; a < aov_count; ++a) channels += size_t(aov_channels(Aov(a)));
  return pixels * channels;
}

[[maybe_unused]] void unpack(Frame& f, const std::vector<uint32_t>& tiles,
                             const std::vector<float>& in) {
  size_t at = 0;
  for (uint32_t t : tiles)
    for (int a = 0; a < aov_count; ++a) {
      FloatImage& img = f.aov[a];
      const size_t c = size_t(img.channels);
      tile_pixels(t, f.width, f.height, [&](size_t p) {
        std::copy(&in[at], &in[at] + c, &img.pixels[p * c]);
        at += c;
      });
    }
}

// Tiles a rank takes at a time: two per thread, so its threads stay busy, but at most an
// eighth of a fair share, so the last chunks (the frame's tail) are short.
[[maybe_unused]] int chunk_tiles(const RenderSettings& s) {
  const int threads = s.threads > 0 ? s.threads : hardware_thread_count();
  const size_t share = render_tile_count(s.width, s.height) / (8 * size_t(std::max(1, world_size)));
  return int(std::clamp<size_t>(share, 1, size_t(2 * threads)));
}

}  // namespace

bool built_with_mpi() {
#ifdef KESTREL_HAVE_MPI
  return true;
#else
  return false;
#endif
}

int rank() {
  return world_rank;
}
int size() {
  return world_size;
}

void init(int* argc, char*** argv) {
#ifdef KESTREL_HAVE_MPI
  if (started || !launched_by_mpirun()) return;
  int provided = 0;
  MPI_Init_thread(argc, argv, MPI_THREAD_SERIALIZED, &provided);
  started = true;
  MPI_Comm_rank(MPI_COMM_WORLD, &world_rank);
  MPI_Comm_size(MPI_COMM_WORLD, &world_size);
  if (provided < MPI_THREAD_SERIALIZED && world_size > 1)
    abort_all("this MPI library does not provide MPI_THREAD_SERIALIZED");
#else
  (void)argc, (void)argv;
#endif
}

void finalize() {
#ifdef KESTREL_HAVE_MPI
  if (started) MPI_Finalize();
  started = false;
#endif
}

void abort_all(const std::string& message) {
  std::fprintf(stderr, "kestrel: rank %d of %d: %s\n", world_rank, world_size, message.c_str());
  std::fflush(stderr);
#ifdef KESTREL_HAVE_MPI
  if (started) MPI_Abort(MPI_COMM_WORLD, 1);
#endif
  std::exit(1);
}

Frame render(Renderer& renderer, const Camera& camera, const RenderSettings& s,
             std::optional<Camera> prev_camera, std::vector<RankStats>* per_rank) {
  if (world_size == 1) {
    Timer t;
    Frame f = renderer.render(camera, s, prev_camera);
    if (per_rank)
      *per_rank = {RankStats{t.ms(), t.ms(), render_tile_count(s.width, s.height), f.stats.rays()}};
    return f;
  }
#ifndef KESTREL_HAVE_MPI
  throw Error(ErrorCode::unsupported, "distributed render without MPI");
#else
  if (s.time_limit_s > 0)
    throw Error(ErrorCode::invalid_argument,
                "render: --time-limit needs one process (every tile needs every pass)");
  RenderSettings local = s;
  local.progress = false;
  Timer wall;
  RankStats mine;
  Frame frame;
  auto render_chunk = [&](const std::vector<uint32_t>& tiles) {
    Timer t;
    renderer.render_tiles(camera, local, tiles, frame, prev_camera);
    mine.busy_ms += t.ms();
    mine.tiles += tiles.size();
  };
  const uint32_t tile_count = uint32_t(render_tile_count(s.width, s.height));
  if (world_rank == 0) {
    // Size the frame before the service thread writes into it.
    renderer.render_tiles(camera, local, std::span<const uint32_t>{}, frame, prev_camera);
    std::mutex queue_mutex;
    uint32_t next = 0;
    auto take = [&](int want) {
      std::lock_guard<std::mutex> lock(queue_mutex);
      std::vector<uint32_t> tiles;
      while (int(tiles.size()) < want && next < tile_count) tiles.push_back(next++);
      return tiles;
    };
    std::exception_ptr service_error;
    std::thread service([&] {
      try {
        std::vector<std::vector<uint32_t> > assigned(static_cast<size_t>(world_size));
        std::vector<int> want(static_cast<size_t>(world_size), 1);
        std::vector<float> buffer;
        int open = world_size - 1;
        while (open > 0) {
          int flag = 0;
          MPI_Status st;
          MPI_Iprobe(MPI_ANY_SOURCE, MPI_ANY_TAG, MPI_COMM_WORLD, &flag, &st);
          if (!flag) {
            std::this_thread::sleep_for(std::chrono::microseconds(200));
            continue;
          }
          const int src = st.MPI_SOURCE;
          if (st.MPI_TAG == tag_request) {
            MPI_Recv(&want[size_t(src)], 1, MPI_INT, src, tag_request, MPI_COMM_WORLD,
                     MPI_STATUS_IGNORE);
          } else if (st.MPI_TAG == tag_result) {
            int count = 0;
            MPI_Get_count(&st, MPI_FLOAT, &count);
            const size_t expected = packed_size(assigned[size_t(src)], s.width, s.height);
            if (size_t(count) != expected)
              throw Error(ErrorCode::io_error, fmt::format("rank {} sent {} values for {} expected",
                                                           src, count, expected));
            buffer.resize(size_t(count));
            MPI_Recv(buffer.data(), count, MPI_FLOAT, src, tag_result, MPI_COMM_WORLD,
                     MPI_STATUS_IGNORE);
            unpack(frame, assigned[size_t(src)], buffer);
          } else {
            throw Error(ErrorCode::io_error,
                        fmt::format("unexpected message (tag {}) from rank {}", st.MPI_TAG, src));
          }
          assigned[size_t(src)] = take(want[size_t(src)]);
          MPI_Send(assigned[size_t(src)].data(), int(assigned[size_t(src)].size()), MPI_UINT32_T,
                   src, tag_work, MPI_COMM_WORLD);
          if (assigned[size_t(src)].empty()) --open;
        }
      } catch (...) {
        service_error = std::current_exception();
      }
    });
    try {
      for (std::vector<uint32_t> tiles = take(chunk_tiles(s)); !tiles.empty();
           tiles = take(chunk_tiles(s)))
        render_chunk(tiles);
    } catch (...) {
      service.join();
      throw;
    }
    service.join();
    if (service_error) std::rethrow_exception(service_error);
  } else {
    const int want = chunk_tiles(s);
    MPI_Send(&want, 1, MPI_INT, 0, tag_request, MPI_COMM_WORLD);
    std::vector<float> buffer;
    for (;;) {
      MPI_Status st;
      MPI_Probe(0, tag_work, MPI_COMM_WORLD, &st);
      int count = 0;
      MPI_Get_count(&st, MPI_UINT32_T, &count);
      std::vector<uint32_t> tiles(static_cast<size_t>(count));
      MPI_Recv(tiles.data(), count, MPI_UINT32_T, 0, tag_work, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
      if (tiles.empty()) break;
      render_chunk(tiles);
      pack(frame, tiles, buffer);
      MPI_Send(buffer.data(), int(buffer.size()), MPI_FLOAT, 0, tag_result, MPI_COMM_WORLD);
    }
  }
  mine.wall_ms = wall.ms();
  mine.rays = frame.stats.rays();
  // Every rank's figures to rank 0: the frame's stats are the sums (the steps too).
  RenderStats::Steps& st = frame.stats.steps;
  constexpr auto step_fields = RenderStats::Steps::fields();
  constexpr int steps = int(step_fields.size()), figures = 8 + steps;
  double local_figures[figures] = {mine.busy_ms,
                                   mine.wall_ms,
                                   double(mine.tiles),
                                   double(frame.stats.camera_rays),
                                   double(frame.stats.bounce_rays),
                                   double(frame.stats.shadow_rays),
                                   frame.stats.trace_ms,
                                   frame.stats.total_thread_ms};
  for (int k = 0; k < steps; ++k) local_figures[8 + k] = st.*step_fields[size_t(k)].second;
  std::vector<double> all(world_rank == 0 ? figures * size_t(world_size) : 0);
  MPI_Gather(local_figures, figures, MPI_DOUBLE, all.data(), figures, MPI_DOUBLE, 0,
             MPI_COMM_WORLD);
  if (world_rank != 0) return Frame{};
  frame.stats.camera_rays = frame.stats.bounce_rays = frame.stats.shadow_rays = 0;
  frame.stats.trace_ms = frame.stats.total_thread_ms = 0;
  st = RenderStats::Steps{};
  if (per_rank) per_rank->clear();
  for (int r = 0; r < world_size; ++r) {
    const double* v = &all[figures * size_t(r)];
    frame.stats.camera_rays += uint64_t(v[3]);
    frame.stats.bounce_rays += uint64_t(v[4]);
    frame.stats.shadow_rays += uint64_t(v[5]);
    frame.stats.trace_ms += v[6];
    frame.stats.total_thread_ms += v[7];
    for (int k = 0; k < steps; ++k) st.*step_fields[size_t(k)].second += v[8 + k];
    if (per_rank)
      per_rank->push_back(RankStats{v[0], v[1], uint64_t(v[2]), uint64_t(v[3] + v[4] + v[5])});
  }
  frame.stats.ms = wall.ms();
  frame.stats.passes = s.spp;
  return frame;
#endif
}

}  // namespace kestrel::distributed
