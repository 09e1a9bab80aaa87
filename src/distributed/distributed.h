// Distributed rendering over MPI (OpenMPI from Debian). Image-parallel: a frame's tiles are
// handed out dynamically by rank 0 -- a worker asks for a chunk, renders every pass of its
// tiles (Renderer::render_tiles, so each pixel is render()'s bits), sends the pixels back
// with its next request -- while rank 0 renders chunks from the same queue between answers.
// Every rank count gives the same bits as one process; rank 0 holds the frame and writes the
// files. Without MPI at configure time, or outside mpirun, everything runs in one process.
// See docs/distributed.md.
#pragma once
#include <optional>
#include <string>
#include <vector>

#include "kestrel/render.h"

namespace kestrel::distributed {

/// Starts MPI when the process was launched by mpirun (its environment says so); a plain
/// run stays one process and never touches MPI. Call once, first thing in main().
void init(int* argc, char*** argv);
/// Ends MPI (after every rank has finished). Safe without init.
void finalize();
/// This process's rank and the number of ranks (0 and 1 outside mpirun).
int rank();
int size();
/// Whether kestrel was built with MPI.
bool built_with_mpi();
/// Ends every rank: prints "kestrel: rank R of N: MESSAGE" and calls MPI_Abort, so mpirun
/// exits non-zero (a plain exit(1) outside mpirun).
[[noreturn]] void abort_all(const std::string& message);

/// What one rank did for a frame.
struct RankStats {
  double busy_ms = 0;  ///< time in render_tiles
  double wall_ms = 0;  ///< the frame, start to end, on that rank
  uint64_t tiles = 0, rays = 0;
};

/// Renders one frame over every rank (each must call it with the same arguments). Rank 0
/// returns the whole frame with stats summed over ranks; other ranks an empty frame
/// (width 0). `per_rank` (rank 0): one entry per rank. With one rank: Renderer::render.
/// A time limit needs one rank (every tile needs every pass): an Error otherwise.
Frame render(Renderer& renderer, const Camera& camera, const RenderSettings& settings,
             std::optional<Camera> prev_camera = std::nullopt,
             std::vector<RankStats>* per_rank = nullptr);

}  // namespace kestrel::distributed
