// `tfmatch bench-stream`: the streamed `optimize` (host/solvers/streamed_optimize.h) on volumes
// generated on disk: per size, two raw float32 files of N voxels are written, then timed are one
// plain read of both files (the I/O bound) and `tfmatch optimize --stream on` run as a child
// process (wall time and peak RSS from wait4); `--stream off` times the whole-volume path
// instead (both fields loaded, then uploaded), the same ratio to a read. The files' page-cache pages are dropped before
// each measurement, so both read from the disk. The files live in a staged directory that is
// removed afterwards, also on an error or an interrupt.
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>

#include "bench_files.h"
#include "cli.h"
#include "output_options.h"
#include "tfmatch/io/atomic_file.h"
#include "tfmatch/io/json.h"
#include "tfmatch/io/output_check.h"
#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/memory_budget.h"

namespace tfm::cli {
namespace {

namespace fs = std::filesystem;

struct BenchArgs {
  std::vector<uint64_t> voxels{100'000'000, 800'000'000};
  std::string dir;  // default: the temporary directory
  std::string solver = "normal-equations";
  std::string stream = "on";  // optimize --stream: on (slabs from disk) or off (loaded whole)
  bool report = false;  // optimize --report too (box-filtered copies, renderings)
  std::string json;
};

int run(const BenchArgs& a) {
  const JsonOutput json(a.json);
  FilePlan().output(json.file(), "--json").check();
  const fs::path base = a.dir.empty() ? fs::temp_directory_path() : fs::path(a.dir);
  if (!fs::is_directory(base)) throw CLI::ValidationError("--dir", base.string() + " is not a directory");
  uint64_t largest = 0;
  for (uint64_t n : a.voxels) largest = std::max(largest, n);
  const std::array<uint64_t, 3> g = bench_grid(largest);
  const uint64_t needed = 2 * g[0] * g[1] * g[2] * sizeof(float) + (uint64_t(256) << 20);
  const uint64_t free_bytes = fs::space(base).available;
  if (free_bytes < needed)
    throw std::runtime_error("bench-stream: " + base.string() + " has " + format_bytes(free_bytes) + " free, the " +
                             std::to_string(largest) + "-voxel files need " + format_bytes(needed) +
                             " (two float32 files); pass --dir on a larger disk or smaller --voxels");
  nlohmann::json rows = nlohmann::json::array();
  const std::array<double, 3> load = load_average();
  {
    OutputBatch scratch;  // never committed: its staged directory and everything in it go at the end
    const fs::path work = scratch.directory(base / ("tfmatch-bench-stream-" + std::to_string(::getpid())));
    std::ofstream(work / "tf.json") << R"({"rgba": [[0,0,0,0],[0.2,0.3,1,0.3],[1,1,0.2,0.6],[1,0.2,0.1,1]]})";

    std::cout << "tfmatch bench-stream: optimize --stream " << a.stream << " (--solver " << a.solver
              << (a.stream == "on" ? ", ranges from the data: 2 passes)" : ", both fields loaded whole, ranges from the data)")
              << (a.report ? ", with --report (512x512)" : "") << " in " << base.string() << "; " << format_bytes(free_bytes) << " free; load average " << load[0] << " "
              << load[1] << " " << load[2] << "; page cache dropped before each run\n";
    std::cout << std::left << std::setw(14) << "voxels" << std::setw(18) << "grid" << std::setw(11) << "files"
              << std::setw(10) << "write s" << std::setw(18) << "read both once s" << std::setw(13) << "optimize s"
              << std::setw(18) << "optimize / read" << "peak RSS\n"
              << std::right;
    for (uint64_t n : a.voxels) {
      const std::array<uint64_t, 3> d = bench_grid(n);
      const uint64_t voxels = d[0] * d[1] * d[2];
      const std::string stem = std::to_string(d[0]) + "x" + std::to_string(d[1]) + "x" + std::to_string(d[2]) + "_float32.raw";
      const fs::path ref = work / ("ref_" + stem), field = work / ("field_" + stem);
      auto t0 = std::chrono::steady_clock::now();
      write_bench_fields(ref, field, d);
      drop_cached_pages(ref);
      drop_cached_pages(field);
      const double write_s = seconds_since(t0);
      const double read_s = read_files({ref, field});
      drop_cached_pages(ref);
      drop_cached_pages(field);
      std::vector<std::string> args{"optimize", "--ref", ref.string(), "--field", field.string(), "--ref-tf",
                                    (work / "tf.json").string(), "--out", (work / "out.json").string(), "--json",
                                    (work / "summary.json").string(), "--stream", a.stream, "--solver", a.solver};
      if (a.report) args.insert(args.end(), {"--report", (work / "report").string(), "--width", "512", "--height", "512"});
      if (memory_budget().source.rfind("--max-memory", 0) == 0)
        args.insert(args.begin(), {"--max-memory", std::to_string(memory_budget().bytes)});
      args.insert(args.begin(), self_path());
      const ChildRun r = run_child(args, work / "optimize.log", "bench-stream");
      if (r.exit_code != 0) {
        std::ifstream log(work / "optimize.log");
        std::cerr << log.rdbuf();
        throw std::runtime_error("bench-stream: tfmatch optimize exited with " + std::to_string(r.exit_code) + " at " +
                                 std::to_string(voxels) + " voxels");
      }
      const std::string grid = std::to_string(d[0]) + "x" + std::to_string(d[1]) + "x" + std::to_string(d[2]);
      std::cout << std::left << std::setw(14) << voxels << std::setw(18) << grid << std::setw(11)
                << format_bytes(2 * voxels * 4) << std::right << std::fixed << std::setprecision(1) << std::setw(7)
                << write_s << "   " << std::setw(8) << read_s << " (" << std::setw(4) << std::setprecision(0)
                << 2.0 * double(voxels) * 4 / read_s / 1e6 << " MB/s)" << std::setprecision(1) << std::setw(8)
                << r.seconds << "     " << std::setw(10) << std::setprecision(2) << r.seconds / read_s << "        "
                << gib(r.peak_rss_bytes) << std::defaultfloat << "\n";
      nlohmann::json summary;
      std::ifstream(work / "summary.json") >> summary;
      rows.push_back({{"voxels", voxels},
                      {"grid", d},
                      {"file_bytes", 2 * voxels * 4},
                      {"write_s", write_s},
                      {"read_once_s", read_s},
                      {"optimize_s", r.seconds},
                      {"optimize_over_read", r.seconds / read_s},
                      {"peak_rss_bytes", r.peak_rss_bytes},
                      {"optimize", summary}});
      fs::remove(ref);
      fs::remove(field);
    }
  }  // the scratch directory is gone
  OutputBatch outputs;
  json.write({{"benchmark", "bench-stream"}, {"load_average", load}, {"dir", base.string()}, {"report", a.report},
              {"stream", a.stream}, {"runs", rows}});
  outputs.commit();
  return 0;
}

CommandRegistration reg(94, [](CLI::App& app) {
  auto args = std::make_shared<BenchArgs>();
  auto* sub = app.add_subcommand("bench-stream", "Benchmark: optimize --stream on generated raw files of N voxels "
                                 "(peak RSS, time, and the time to read both files once)");
  sub->add_option("--voxels", args->voxels, "Voxel counts, comma separated (grids of x = y = 1.25 z)")
      ->delimiter(',')->check(CLI::Range(uint64_t(8), uint64_t(1) << 36))->capture_default_str();
  sub->add_option("--dir", args->dir, "Where the files are written (default: the temporary directory); removed after");
  sub->add_option("--solver", args->solver, "normal-equations or qp")->check(CLI::IsMember({"normal-equations", "qp"}))
      ->capture_default_str();
  sub->add_option("--stream", args->stream, "optimize --stream: on (slab by slab from disk) or off (both fields "
                  "loaded whole: the ratio to a read of the whole-volume path)")
      ->check(CLI::IsMember({"on", "off"}))->capture_default_str();
  sub->add_flag("--report", args->report, "Also write optimize's report (512x512 renderings of box-filtered copies)");
  add_json_option(sub, args->json, "the measurements");
  sub->callback([args] { exit_code() = run(*args); });
});

}  // namespace
}  // namespace tfm::cli
