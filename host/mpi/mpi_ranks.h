// The ranks of an MPI job (OpenMPI, MPICH, ...) behind the model's Ranks interface
// (host/model/ranks.h). Only the command line creates them; library code sees a Ranks.
#pragma once

#include <exception>
#include <functional>
#include <string>

#include "tfmatch/model/ranks.h"

namespace tfm {

class MpiRanks final : public Ranks {
 public:
  // Whether a launcher started this process as part of a job (mpirun/mpiexec of OpenMPI or MPICH,
  // srun with PMI or PMIx): the variables they set. Without one tfmatch runs as one process and
  // never initializes MPI, so the same binary works with and without a launcher.
  static bool launched();
  // How a failing rank's exception reads and which exit code it means (the command line's).
  struct Failure {
    std::string message;
    int exit_code = 1;
  };
  using Describe = std::function<Failure(std::exception_ptr)>;
  // Initializes MPI (only the main thread calls it: MPI_THREAD_FUNNELED) on MPI_COMM_WORLD.
  // Throws std::runtime_error when MPI cannot start.
  MpiRanks(int& argc, char**& argv, Describe describe);
  ~MpiRanks() override;  // MPI_Finalize
  MpiRanks(const MpiRanks&) = delete;
  MpiRanks& operator=(const MpiRanks&) = delete;

  int rank() const override { return rank_; }
  int size() const override { return size_; }
  int local_rank() const override { return local_rank_; }
  void agree(std::exception_ptr local) override;
  void sum(std::span<uint64_t> values) override;
  void min(std::span<double> values) override;
  void max(std::span<double> values) override;
  void sum(std::span<double> values) override;
  std::vector<float> gather(std::span<const float> values) override;

 private:
  Describe describe_;
  int rank_ = 0, size_ = 1, local_rank_ = 0;
  bool agreed_failure_ = false;
};

}  // namespace tfm
