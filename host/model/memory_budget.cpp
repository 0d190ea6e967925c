// The memory budget: resident memory from /proc, available memory from /proc/meminfo and the
// cgroup limit, and the check made before large allocations.
#include "tfmatch/model/memory_budget.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <mutex>
#include <sstream>
#include <utility>

#include <sys/resource.h>
#include <unistd.h>

#include "tfmatch/model/parameter_names.h"

namespace tfm {
namespace {

std::mutex g_mutex;
std::optional<MemoryBudget> g_budget;  // guarded by g_mutex; empty until set or first asked
uint64_t g_reserved = 0;                // MemoryReservation's, guarded by g_mutex
std::string g_reserved_for;             // what the reservations are for, for messages

std::optional<uint64_t> read_number(const char* path) {
  std::ifstream in(path);
  std::string word;
  if (!(in >> word) || word.empty() || !std::all_of(word.begin(), word.end(), ::isdigit)) return std::nullopt;
  try {
    return std::stoull(word);
  } catch (const std::exception&) {
    return std::nullopt;  // "max" or out of range: no limit
  }
}

// Room left under the cgroup's limit, when the process runs in a limited cgroup (containers):
// /proc/meminfo shows the whole machine there.
std::optional<uint64_t> cgroup_room() {
  const std::pair<const char*, const char*> files[] = {
      {"/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"},                                  // v2
      {"/sys/fs/cgroup/memory/memory.limit_in_bytes", "/sys/fs/cgroup/memory/memory.usage_in_bytes"}};  // v1
  for (auto [limit_file, usage_file] : files) {
    const auto limit = read_number(limit_file), usage = read_number(usage_file);
    // v1 reports "no limit" as a huge number.
    if (limit && usage && *limit < (uint64_t(1) << 60)) return *limit > *usage ? *limit - *usage : 0;
  }
  return std::nullopt;
}

}  // namespace

uint64_t resident_memory() {
  std::FILE* f = std::fopen("/proc/self/statm", "r");
  if (!f) return 0;
  unsigned long long size = 0, resident = 0;
  const int got = std::fscanf(f, "%llu %llu", &size, &resident);
  std::fclose(f);
  return got == 2 ? resident * uint64_t(::sysconf(_SC_PAGESIZE)) : 0;
}

uint64_t peak_resident_memory() {
  rusage usage{};
  if (::getrusage(RUSAGE_SELF, &usage) != 0) return 0;
  return uint64_t(usage.ru_maxrss) * 1024;  // KiB on Linux
}

uint64_t available_memory() {
  std::ifstream in("/proc/meminfo");
  std::string key, unit;
  uint64_t value = 0, available = 0;
  while (in >> key >> value) {
    std::getline(in, unit);
    if (key == "MemAvailable:") {
      available = value * 1024;  // kB
      break;
    }
  }
  if (const auto room = cgroup_room()) available = available ? std::min(available, *room) : *room;
  return available;
}

void set_memory_budget(uint64_t bytes, std::string source) {
  std::lock_guard lock(g_mutex);
  if (bytes == 0) g_budget.reset();
  else g_budget = MemoryBudget{bytes, std::move(source)};
}

MemoryBudget memory_budget() {
  std::lock_guard lock(g_mutex);
  if (!g_budget) {
    const uint64_t available = available_memory();
    // Unknown (no /proc): no limit rather than a wrong one.
    g_budget = available ? MemoryBudget{available + resident_memory(), "the memory available when tfmatch started"}
                         : MemoryBudget{UINT64_MAX, "no limit: available memory unknown"};
  }
  return *g_budget;
}

MemoryReservation::MemoryReservation(uint64_t bytes, std::string what) : bytes_(bytes), what_(std::move(what)) {
  std::lock_guard lock(g_mutex);
  g_reserved += bytes_;
  g_reserved_for = what_;
}

void MemoryReservation::release() {
  std::lock_guard lock(g_mutex);
  g_reserved -= std::exchange(bytes_, 0);
}

void check_memory(uint64_t bytes, const std::string& what) {
  const MemoryBudget budget = memory_budget();
  uint64_t reserved = 0;
  std::string reserved_for;
  {
    std::lock_guard lock(g_mutex);
    reserved = g_reserved;
    if (reserved) reserved_for = g_reserved_for;
  }
  const uint64_t resident = resident_memory(), in_use = resident + reserved;
  if (bytes <= budget.bytes && in_use <= budget.bytes - bytes) return;
  const std::string aside = reserved ? " (" + format_bytes(reserved) + " of them set aside for " + reserved_for + ")" : "";
  throw MemoryBudgetExceeded(what + ": needs " + format_bytes(bytes) + ", but the memory budget is " +
                             format_bytes(budget.bytes) + " (" + budget.source + ") and " + format_bytes(in_use) +
                             " are in use" + aside + "; raise it with " + parameter("max-memory") +
                             " if the machine has the memory");
}

std::string format_bytes(uint64_t bytes) {
  if (bytes < 1024) return std::to_string(bytes) + " bytes";
  static const char* units[] = {"KiB", "MiB", "GiB", "TiB", "PiB", "EiB"};
  double v = double(bytes);
  int u = -1;
  while (v >= 1024 && u < 5) v /= 1024, ++u;
  char buf[32];
  std::snprintf(buf, sizeof buf, v < 10 ? "%.2f %s" : v < 100 ? "%.1f %s" : "%.0f %s", v, units[u]);
  return buf;
}

std::optional<uint64_t> parse_byte_size(std::string_view text) {
  std::string s(text);
  // Digits with at most one decimal point: std::stod alone also reads "0x10" (hex) and "1e3".
  size_t used = 0;
  bool point = false;
  for (; used < s.size(); ++used) {
    if (s[used] == '.' && !point) point = true;
    else if (!std::isdigit(static_cast<unsigned char>(s[used]))) break;
  }
  if (used == 0 || (used == 1 && point)) return std::nullopt;
  double number = 0;
  try {
    number = std::stod(s.substr(0, used));
  } catch (const std::exception&) {
    return std::nullopt;
  }
  std::string unit = s.substr(used);
  std::transform(unit.begin(), unit.end(), unit.begin(), [](unsigned char c) { return std::tolower(c); });
  if (unit.size() > 1 && unit.back() == 'b') unit.pop_back();     // "GB", "GiB"
  if (unit.size() > 1 && unit.back() == 'i') unit.pop_back();     // "Gi"
  static const std::pair<const char*, double> scales[] = {{"", 1},           {"b", 1},
                                                          {"k", 0x1p10},     {"m", 0x1p20},
                                                          {"g", 0x1p30},     {"t", 0x1p40}};
  for (auto [name, scale] : scales)
    if (unit == name) {
      const double bytes = std::floor(number * scale);
      if (!(bytes >= 1) || bytes >= 0x1p63) return std::nullopt;
      return uint64_t(bytes);
    }
  return std::nullopt;
}

}  // namespace tfm
