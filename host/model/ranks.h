// The processes a run is split over: the ranks of an MPI job (host/mpi), or this process alone.
// Library code that can run distributed (the streamed optimize) takes a Ranks and calls its
// collectives in the same order on every rank; it never names MPI, so it builds and runs without
// it. Each rank takes a contiguous range of z-slices (rank_slices) and the sums are reduced:
// exact integer sums (the assembly's 32.32 fixed-point words) give the same bits for any number
// of ranks.
//
// Failure protocol: before each reduction, and once at the end of a command, every rank calls
// agree() with what went wrong on it (or nothing). If any rank failed, every rank throws the same
// RankFailure (the lowest failing rank's message and exit code) and calls no further collective:
// a failing rank never leaves the others waiting, and none writes an output.
#pragma once

#include <cstdint>
#include <exception>
#include <span>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "tfmatch/model/volume.h"

namespace tfm {

// What every rank throws when a rank failed (after agree()).
class RankFailure : public std::runtime_error {
 public:
  RankFailure(int rank, int exit_code, const std::string& message)
      : std::runtime_error(message), rank_(rank), exit_code_(exit_code) {}
  int failing_rank() const { return rank_; }
  int exit_code() const { return exit_code_; }

 private:
  int rank_, exit_code_;
};

class Ranks {
 public:
  virtual ~Ranks() = default;
  virtual int rank() const = 0;
  virtual int size() const = 0;
  // This rank's index among the ranks on its node (which of the node's GPUs it takes).
  virtual int local_rank() const = 0;

  // Collective: see the failure protocol above. `local` is this rank's exception, or null.
  // With one rank: rethrows `local` as it is.
  virtual void agree(std::exception_ptr local) = 0;
  // Collectives, elementwise over ranks, the result on every rank: integer sums modulo 2^64 (the
  // same bits in any order), minimum and maximum.
  virtual void sum(std::span<uint64_t> values) = 0;
  virtual void min(std::span<double> values) = 0;
  virtual void max(std::span<double> values) = 0;
  // Sums of doubles. Not associative in general: callers pass values to which at most one rank
  // contributes a nonzero (x + 0 = x exactly), so the result is that rank's bits.
  virtual void sum(std::span<double> values) = 0;
  // Every rank's values one after the other in rank order, on rank 0 (empty on the others).
  virtual std::vector<float> gather(std::span<const float> values) = 0;
};

// This process alone: rank 0 of 1; collectives leave the values as they are.
Ranks& single_rank();

// Collective, and the first one a command calls on its files: unless every rank reads the grid
// rank 0 reads (dims, spacing, origin) and, where `members` is given, as many members, every rank
// throws the RankFailure of the first rank that differs, naming `what` (the files) and both grids.
// A node with another copy of a file would otherwise compute its share of another field and the
// job would write a mixture of the two. It agrees first, so a rank that failed before it stops
// every rank there. Nothing to compare with one rank.
void require_same_grid_on_every_rank(Ranks& ranks, const Volume& grid, const std::string& what, uint64_t members = 0);

// The z-slices [first, end) rank `rank` of `size` takes of `slices`: contiguous, in rank order,
// as even as whole blocks of `block` slices allow (the last block may be short); a rank beyond
// the blocks gets none (first == end).
std::pair<uint64_t, uint64_t> rank_slices(uint64_t slices, int rank, int size, uint64_t block = 1);

}  // namespace tfm
