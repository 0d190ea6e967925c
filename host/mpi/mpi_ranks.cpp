// MPI_COMM_WORLD as Ranks (host/mpi/mpi_ranks.h).
#include "tfmatch/mpi/mpi_ranks.h"

#include <mpi.h>

#include <climits>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <vector>

namespace tfm {

namespace {

// Every MPI call here either succeeds or ends the job (MPI's default error handler aborts all
// ranks), which is what a broken interconnect should do; the return codes are checked anyway.
void check(int rc, const char* what) {
  if (rc != MPI_SUCCESS) throw std::runtime_error(std::string("MPI: ") + what + " failed");
}

}  // namespace

bool MpiRanks::launched() {
  for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_RANK", "PMI_SIZE", "MPI_LOCALNRANKS"})
    if (std::getenv(name)) return true;
  return false;
}

MpiRanks::MpiRanks(int& argc, char**& argv, Describe describe) : describe_(std::move(describe)) {
  int provided = 0;
  check(MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided), "MPI_Init_thread");
  check(MPI_Comm_rank(MPI_COMM_WORLD, &rank_), "MPI_Comm_rank");
  check(MPI_Comm_size(MPI_COMM_WORLD, &size_), "MPI_Comm_size");
  // The ranks sharing this node's memory: their order picks this rank's GPU.
  MPI_Comm node = MPI_COMM_NULL;
  check(MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, rank_, MPI_INFO_NULL, &node), "MPI_Comm_split_type");
  check(MPI_Comm_rank(node, &local_rank_), "MPI_Comm_rank");
  MPI_Comm_free(&node);
}

MpiRanks::~MpiRanks() {
  int finalized = 0;
  MPI_Finalized(&finalized);
  if (!finalized) MPI_Finalize();
}

void MpiRanks::agree(std::exception_ptr local) {
  if (agreed_failure_) throw std::logic_error("MpiRanks::agree after a failure was agreed (no collective may follow)");
  const int mine = local ? rank_ : INT_MAX;
  int lowest = INT_MAX;
  check(MPI_Allreduce(&mine, &lowest, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD), "MPI_Allreduce");
  if (lowest == INT_MAX) return;
  agreed_failure_ = true;
  // The lowest failing rank tells every rank what went wrong there.
  Failure f;
  if (rank_ == lowest) f = describe_(local);
  int header[2] = {f.exit_code, int(f.message.size())};
  check(MPI_Bcast(header, 2, MPI_INT, lowest, MPI_COMM_WORLD), "MPI_Bcast");
  std::vector<char> text(size_t(header[1]) + 1, '\0');
  if (rank_ == lowest) f.message.copy(text.data(), f.message.size());
  check(MPI_Bcast(text.data(), header[1], MPI_CHAR, lowest, MPI_COMM_WORLD), "MPI_Bcast");
  const std::string message = size_ > 1 ? "rank " + std::to_string(lowest) + ": " + text.data() : text.data();
  throw RankFailure(lowest, header[0], message);
}

// MPI_SUM on MPI_UINT64_T adds as C's unsigned arithmetic does in OpenMPI and MPICH (modulo 2^64),
// but the standard leaves overflow to the implementation: an operation of our own says it.
namespace {
void wrapping_sum(void* in, void* inout, int* count, MPI_Datatype*) {
  const uint64_t* a = static_cast<const uint64_t*>(in);
  uint64_t* b = static_cast<uint64_t*>(inout);
  for (int i = 0; i < *count; ++i) b[i] += a[i];
}
}  // namespace

void MpiRanks::sum(std::span<uint64_t> values) {
  MPI_Op op = MPI_OP_NULL;
  check(MPI_Op_create(&wrapping_sum, 1, &op), "MPI_Op_create");
  const int rc = MPI_Allreduce(MPI_IN_PLACE, values.data(), int(values.size()), MPI_UINT64_T, op, MPI_COMM_WORLD);
  MPI_Op_free(&op);
  check(rc, "MPI_Allreduce");
}

void MpiRanks::min(std::span<double> values) {
  check(MPI_Allreduce(MPI_IN_PLACE, values.data(), int(values.size()), MPI_DOUBLE, MPI_MIN, MPI_COMM_WORLD),
        "MPI_Allreduce");
}

void MpiRanks::max(std::span<double> values) {
  check(MPI_Allreduce(MPI_IN_PLACE, values.data(), int(values.size()), MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD),
        "MPI_Allreduce");
}

void MpiRanks::sum(std::span<double> values) {
  check(MPI_Allreduce(MPI_IN_PLACE, values.data(), int(values.size()), MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD),
        "MPI_Allreduce");
}

std::vector<float> MpiRanks::gather(std::span<const float> values) {
  // Every rank's count first, to every rank, so that all of them refuse alike what MPI_Gatherv's
  // int counts and offsets cannot hold (a refusal on rank 0 alone, between two collectives, left
  // the others inside the second).
  const uint64_t mine64 = values.size();
  std::vector<uint64_t> sizes(size_t(size_), 0);
  check(MPI_Allgather(&mine64, 1, MPI_UINT64_T, sizes.data(), 1, MPI_UINT64_T, MPI_COMM_WORLD), "MPI_Allgather");
  uint64_t total = 0;
  for (uint64_t n : sizes) total += n;
  if (total > uint64_t(INT_MAX))
    throw std::runtime_error("MPI: the gathered field has " + std::to_string(total) +
                             " values, past MPI_Gatherv's 2^31 - 1 (write .pvti pieces instead)");
  const int mine = int(mine64);
  std::vector<int> counts, offsets;
  std::vector<float> all;
  if (rank_ == 0) {
    int at = 0;
    for (uint64_t n : sizes) counts.push_back(int(n)), offsets.push_back(at), at += int(n);
    all.resize(total);
  }
  check(MPI_Gatherv(values.data(), mine, MPI_FLOAT, all.data(), counts.data(), offsets.data(), MPI_FLOAT, 0,
                    MPI_COMM_WORLD),
        "MPI_Gatherv");
  return all;
}

}  // namespace tfm
