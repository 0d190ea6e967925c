// Ranks (host/model/ranks.h) as threads of one test process: R threads, one ThreadRanks each,
// whose collectives meet at a barrier. Reductions add in rank order on every rank, and agree()
// follows the failure protocol, so library code that runs distributed can be tested for the bits
// and the failure handling of any number of ranks without MPI.
#pragma once

#include <algorithm>
#include <barrier>
#include <climits>
#include <cstdint>
#include <exception>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "tfmatch/model/ranks.h"

namespace tfm::test {

class ThreadRanks final : public Ranks {
 public:
  // What the R ranks share: the barrier and each rank's contribution to the current collective.
  struct Shared {
    explicit Shared(int ranks) : size(ranks), barrier(ranks), doubles(size_t(ranks)), words(size_t(ranks)),
                                 failures(size_t(ranks)) {}
    int size;
    std::barrier<> barrier;
    std::vector<std::vector<double>> doubles;
    std::vector<std::vector<uint64_t>> words;
    std::vector<std::string> failures;  // "" where the rank did not fail
  };
  ThreadRanks(std::shared_ptr<Shared> shared, int rank) : shared_(std::move(shared)), rank_(rank) {}

  int rank() const override { return rank_; }
  int size() const override { return shared_->size; }
  int local_rank() const override { return rank_; }

  void agree(std::exception_ptr local) override {
    std::string text;
    if (local) {
      try {
        std::rethrow_exception(local);
      } catch (const std::exception& e) {
        text = e.what();
      } catch (...) {
        text = "unknown failure";
      }
      if (text.empty()) text = "(no message)";
    }
    shared_->failures[size_t(rank_)] = text;
    shared_->barrier.arrive_and_wait();
    int lowest = INT_MAX;
    for (int r = 0; r < size(); ++r)
      if (!shared_->failures[size_t(r)].empty()) lowest = std::min(lowest, r);
    const std::string message = lowest == INT_MAX ? "" : shared_->failures[size_t(lowest)];
    shared_->barrier.arrive_and_wait();
    if (lowest != INT_MAX) throw RankFailure(lowest, 1, "rank " + std::to_string(lowest) + ": " + message);
  }
  void sum(std::span<uint64_t> values) override {
    reduce(shared_->words, values, [](uint64_t a, uint64_t b) { return a + b; });
  }
  void min(std::span<double> values) override {
    reduce(shared_->doubles, values, [](double a, double b) { return std::min(a, b); });
  }
  void max(std::span<double> values) override {
    reduce(shared_->doubles, values, [](double a, double b) { return std::max(a, b); });
  }
  void sum(std::span<double> values) override {
    reduce(shared_->doubles, values, [](double a, double b) { return a + b; });
  }

  std::vector<float> gather(std::span<const float> values) override {
    std::vector<double> mine(values.begin(), values.end());
    shared_->doubles[size_t(rank_)] = mine;
    shared_->barrier.arrive_and_wait();
    std::vector<float> all;
    if (rank_ == 0)
      for (int r = 0; r < size(); ++r)
        for (double v : shared_->doubles[size_t(r)]) all.push_back(float(v));
    shared_->barrier.arrive_and_wait();
    return all;
  }

  // Runs body(ranks) on R threads, one ThreadRanks each, and waits for all.
  static void run(int ranks, const std::function<void(ThreadRanks&)>& body) {
    auto shared = std::make_shared<Shared>(ranks);
    std::vector<std::thread> threads;
    for (int r = 0; r < ranks; ++r)
      threads.emplace_back([shared, r, &body] {
        ThreadRanks me(shared, r);
        body(me);
      });
    for (std::thread& t : threads) t.join();
  }

 private:
  template <class T, class Op>
  void reduce(std::vector<std::vector<T>>& slots, std::span<T> values, Op op) {
    slots[size_t(rank_)].assign(values.begin(), values.end());
    shared_->barrier.arrive_and_wait();
    for (size_t i = 0; i < values.size(); ++i) {
      T total = slots[0][i];
      for (int r = 1; r < size(); ++r) total = op(total, slots[size_t(r)][i]);
      values[i] = total;
    }
    shared_->barrier.arrive_and_wait();
  }
  std::shared_ptr<Shared> shared_;
  int rank_;
};

}  // namespace tfm::test
