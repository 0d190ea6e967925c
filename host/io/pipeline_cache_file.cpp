// The on-disk pipeline cache: an 8-byte magic, the data's length and CRC-32 (zlib), the data.
#include "tfmatch/io/pipeline_cache_file.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <system_error>

#include <unistd.h>
#include <zlib.h>

namespace fs = std::filesystem;

namespace tfm {
namespace {

constexpr std::array<char, 8> kMagic = {'T', 'F', 'M', 'P', 'C', 'A', 'C', '1'};
constexpr size_t kHeaderBytes = kMagic.size() + 8 + 4;
// No driver's cache of tfmatch's few dozen kernels comes near this; a larger file is not ours.
constexpr uint64_t kMaxDataBytes = uint64_t(256) << 20;

uint32_t checksum(std::span<const uint8_t> data) {
  uLong crc = crc32(0L, Z_NULL, 0);
  // zlib takes a uInt length: fed in pieces below 4 GiB (always one piece here).
  for (size_t done = 0; done < data.size();) {
    const size_t n = std::min<size_t>(data.size() - done, 1u << 30);
    crc = crc32(crc, data.data() + done, static_cast<uInt>(n));
    done += n;
  }
  return static_cast<uint32_t>(crc);
}

template <class T>
void put(std::string& out, T value) {
  out.append(reinterpret_cast<const char*>(&value), sizeof value);
}

template <class T>
T get(const std::string& in, size_t at) {
  T value{};
  std::memcpy(&value, in.data() + at, sizeof value);
  return value;
}

}  // namespace

std::optional<fs::path> pipeline_cache_directory() {
  if (const char* own = std::getenv("TFMATCH_PIPELINE_CACHE"); own && *own) {
    const std::string v = own;
    if (v == "off" || v == "0") return std::nullopt;
    return fs::path(v);
  }
  if (const char* xdg = std::getenv("XDG_CACHE_HOME"); xdg && *xdg && fs::path(xdg).is_absolute())
    return fs::path(xdg) / "tfmatch" / "pipelines";
  if (const char* home = std::getenv("HOME"); home && *home) return fs::path(home) / ".cache" / "tfmatch" / "pipelines";
  return std::nullopt;
}

fs::path pipeline_cache_path(const fs::path& dir, const std::string& device_identity, uint64_t shaders_fingerprint) {
  char key[17];
  std::snprintf(key, sizeof key, "%016llx", static_cast<unsigned long long>(shaders_fingerprint));
  return dir / (device_identity + "-" + key + ".bin");
}

StoredPipelineCache read_pipeline_cache(const fs::path& file) {
  StoredPipelineCache out;
  std::error_code ec;
  if (!fs::exists(file, ec)) return out;
  const auto ignored = [&](const std::string& why) {
    out.note = "pipeline cache " + file.string() + " ignored: " + why;
    out.data.clear();
    return out;
  };
  // A directory opens as a stream on Linux, and its "size" is then nonsense.
  if (!fs::is_regular_file(file, ec)) return ignored(fs::is_directory(file, ec) ? "a directory, not a file" : "not a regular file");
  // The size of the file this stream opened: a writer renames a new file into place (never
  // rewrites one), so the open file stays whole while another takes its name; asking the path
  // for the size first could see the next file's.
  std::ifstream in(file, std::ios::binary | std::ios::ate);
  if (!in) return ignored("cannot be read");
  const std::streamoff end = in.tellg();
  const uintmax_t size = end < 0 ? 0 : uintmax_t(end);
  if (size < kHeaderBytes || size > kHeaderBytes + kMaxDataBytes)
    return ignored("its size (" + std::to_string(size) + " bytes) is not that of a tfmatch pipeline cache");
  in.seekg(0);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (!in && !in.eof()) return ignored("cannot be read");
  if (bytes.size() != size) return ignored("changed while it was read");
  if (std::memcmp(bytes.data(), kMagic.data(), kMagic.size()) != 0) return ignored("not a tfmatch pipeline cache");
  const uint64_t length = get<uint64_t>(bytes, kMagic.size());
  if (length != size - kHeaderBytes)
    return ignored("truncated or extended (" + std::to_string(size - kHeaderBytes) + " bytes of data, header says " +
                   std::to_string(length) + ")");
  out.data.assign(bytes.begin() + kHeaderBytes, bytes.end());
  if (checksum(out.data) != get<uint32_t>(bytes, kMagic.size() + 8)) return ignored("damaged (checksum differs)");
  return out;
}

std::string write_pipeline_cache(const fs::path& file, std::span<const uint8_t> data) {
  std::string bytes(kMagic.data(), kMagic.size());
  put<uint64_t>(bytes, data.size());
  put<uint32_t>(bytes, checksum(data));
  bytes.append(reinterpret_cast<const char*>(data.data()), data.size());
  // Not write_file_atomically (atomic_file.h): that one belongs to a command's outputs, which an
  // interrupt or a failed run removes; a cache is written after the run, whatever its outcome.
  std::error_code ec;
  fs::create_directories(file.parent_path(), ec);
  if (ec) return "cannot create " + file.parent_path().string() + ": " + ec.message();
  static std::atomic<uint64_t> counter{0};  // several writers in one process (tests) stay apart
  const fs::path temporary = file.parent_path() / ("." + file.filename().string() + ".tmp-" +
                                                   std::to_string(::getpid()) + "-" + std::to_string(counter++));
  {
    std::ofstream out(temporary, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    out.close();
    if (!out) {
      fs::remove(temporary, ec);
      return "cannot write " + temporary.string();
    }
  }
  fs::rename(temporary, file, ec);  // atomic: readers see the old file or the new one, whole
  if (ec) {
    const std::string why = "cannot rename " + temporary.string() + " to " + file.string() + ": " + ec.message();
    fs::remove(temporary, ec);
    return why;
  }
  return {};
}

}  // namespace tfm
