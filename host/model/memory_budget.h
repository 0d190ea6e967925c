// The process's memory budget (`--max-memory`; default: the memory available on the machine when
// first asked). Every allocation whose size an input decides (decoded volumes, decompressed
// streams, images) is checked against it before it is made, so that a small
// hostile file cannot make tfmatch allocate gigabytes, and a large real one fails with a message
// instead of std::bad_alloc. Device buffers: kernels/device_memory.h.
#pragma once

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>

namespace tfm {

// What check_memory() throws; the message names what asked, the size, the budget and its source.
class MemoryBudgetExceeded : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct MemoryBudget {
  uint64_t bytes = 0;  // the most this process may hold (resident) after an allocation
  std::string source;  // where the number comes from, as messages say it ("--max-memory 1G")
};

// The smallest budget a user may set: tfmatch holds about 12 MiB before it reads anything.
inline constexpr uint64_t kMinMemoryBudget = uint64_t(16) << 20;

// Sets the budget; `bytes` = 0 goes back to the default. `source` is what messages quote.
void set_memory_budget(uint64_t bytes, std::string source);
// The budget now. The default is fixed on first use: the memory available then
// (available_memory()) plus what the process already holds.
MemoryBudget memory_budget();

// Throws MemoryBudgetExceeded "<what>: needs <bytes>, but ..." when the process's resident memory
// plus `bytes` exceeds the budget. Cheap (one read of /proc/self/statm): call it right before
// each large allocation.
void check_memory(uint64_t bytes, const std::string& what);

// Memory that work running now on another thread is about to take (a device starting while the
// inputs are read): check_memory() counts it as in use until release() or destruction, so that a
// check made meanwhile leaves room for it (optimize's load check saw 13.5 MiB in use, and the
// device's ~60 MiB arrived after it).
class MemoryReservation {
 public:
  MemoryReservation(uint64_t bytes, std::string what);
  ~MemoryReservation() { release(); }
  MemoryReservation(const MemoryReservation&) = delete;
  MemoryReservation& operator=(const MemoryReservation&) = delete;
  void release();

 private:
  uint64_t bytes_;
  std::string what_;
};

// MemAvailable of /proc/meminfo, capped by the cgroup (v2 or v1) memory limit; 0 when unknown.
uint64_t available_memory();
// This process's resident set size now; 0 when unknown.
uint64_t resident_memory();
// The most this process has held resident so far (getrusage's ru_maxrss); 0 when unknown.
uint64_t peak_resident_memory();

// "1.5 GiB", "12 MiB", "512 bytes".
std::string format_bytes(uint64_t bytes);
// "2G", "512M", "1.5GiB", "64k", "1000000" (bytes; K/M/G/T are powers of 1024, with or without
// "iB"/"B"). nullopt for anything else, for zero and for sizes past 2^63.
std::optional<uint64_t> parse_byte_size(std::string_view text);

}  // namespace tfm
