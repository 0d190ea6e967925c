// read_volume FILE[:VARIABLE]...: what tfmatch reads from each file (grid, axes, value range, no-data
// count) through tfmatch::io alone, with no GPU code in the program. Exit 1 with the library's
// message (file name first) when a file cannot be read.
#include <cstdio>
#include <exception>

#include <tfmatch/model/field_mapping.h>
#include <tfmatch/io/volume_io.h>

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: read_volume FILE[:VARIABLE]...\n");
    return 2;
  }
  for (int i = 1; i < argc; ++i) {
    try {
      const tfm::Volume v = tfm::load_volume(argv[i]);
      const tfm::FiniteStats s = tfm::finite_stats(v.values);
      std::printf("%s: %llu x %llu x %llu", argv[i], static_cast<unsigned long long>(v.dims[0]),
                  static_cast<unsigned long long>(v.dims[1]), static_cast<unsigned long long>(v.dims[2]));
      for (const tfm::GridAxis& axis : v.axes)
        if (!axis.name.empty()) std::printf(" %s", axis.name.c_str());
      std::printf(", values %.6g .. %.6g, %llu no data\n", s.lo, s.hi, static_cast<unsigned long long>(s.nan));
    } catch (const std::exception& e) {
      std::fprintf(stderr, "read_volume: %s\n", e.what());
      return 1;
    }
  }
  std::printf("OK\n");
  return 0;
}
