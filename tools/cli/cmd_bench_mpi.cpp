// `tfmatch bench-mpi`: `optimize --stream on` split over 1, 2, 4, ... MPI ranks (docs/mpi.md) on
// a generated raw pair, each run through the launcher (by default `mpirun --oversubscribe -n R`;
// `srun -n {ranks}` on a cluster), beside the same run without a launcher. Per rank count: wall
// time from the launcher's start to its end, the speed-up over the run without a launcher, each
// rank's peak memory (from the run's JSON), and whether the TF file is byte-identical to the run
// without a launcher.
// The files stay in the page cache between runs (the runs measure the ranks, not the disk); they
// live in a staged directory removed afterwards, also on an error or an interrupt.
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <iterator>
#include <sstream>
#include <thread>

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

struct BenchMpiArgs {
  uint64_t voxels = 20'000'000;
  std::vector<int> ranks{1, 2, 4};
  std::string launcher = "mpirun --oversubscribe -n {ranks}";
  std::string dir;  // default: the temporary directory
  std::string json;
};

std::string read_file(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// The launcher's words with {ranks} replaced, split at spaces.
std::vector<std::string> launcher_words(const std::string& launcher, int ranks) {
  std::vector<std::string> words;
  std::istringstream in(launcher);
  for (std::string w; in >> w;) {
    for (size_t at; (at = w.find("{ranks}")) != std::string::npos;) w.replace(at, 7, std::to_string(ranks));
    words.push_back(w);
  }
  return words;
}

int run(const BenchMpiArgs& a) {
  const JsonOutput json(a.json);
  FilePlan().output(json.file(), "--json").check();
  if (a.launcher.find("{ranks}") == std::string::npos)
    throw CLI::ValidationError("--launcher", "needs {ranks} where the rank count goes, e.g. 'srun -n {ranks}'");
  const fs::path base = a.dir.empty() ? fs::temp_directory_path() : fs::path(a.dir);
  if (!fs::is_directory(base)) throw CLI::ValidationError("--dir", base.string() + " is not a directory");
  const std::array<uint64_t, 3> d = bench_grid(a.voxels);
  const uint64_t voxels = d[0] * d[1] * d[2];
  const uint64_t needed = 2 * voxels * sizeof(float) + (uint64_t(64) << 20);
  if (fs::space(base).available < needed)
    throw std::runtime_error("bench-mpi: " + base.string() + " has " + format_bytes(fs::space(base).available) +
                             " free, the files need " + format_bytes(needed) + "; pass --dir or smaller --voxels");
  // OpenMPI refuses to start as root unless told (containers and CI machines run as root).
  if (::geteuid() == 0) {
    ::setenv("OMPI_ALLOW_RUN_AS_ROOT", "1", 0);
    ::setenv("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1", 0);
  }
  const std::array<double, 3> load = load_average();
  const unsigned cores = std::max(1u, std::thread::hardware_concurrency());
  nlohmann::json rows = nlohmann::json::array();
  {
    OutputBatch scratch;  // never committed: its staged directory goes at the end
    const fs::path work = scratch.directory(base / ("tfmatch-bench-mpi-" + std::to_string(::getpid())));
    std::ofstream(work / "tf.json") << R"({"rgba": [[0,0,0,0],[0.2,0.3,1,0.3],[1,1,0.2,0.6],[1,0.2,0.1,1]]})";
    const std::string grid = std::to_string(d[0]) + "x" + std::to_string(d[1]) + "x" + std::to_string(d[2]);
    const fs::path ref = work / ("ref_" + grid + "_float32.raw"), field = work / ("field_" + grid + "_float32.raw");
    write_bench_fields(ref, field, d);
    const double read_s = read_files({ref, field});  // and into the page cache
    std::cout << "tfmatch bench-mpi: optimize --stream on of " << voxels << " voxels (" << grid << ", "
              << format_bytes(2 * voxels * 4) << " in two raw files, in the page cache; one read " << std::fixed
              << std::setprecision(2) << read_s << " s); " << cores << " cores; load average " << load[0] << " "
              << load[1] << " " << load[2] << std::defaultfloat << "\n";
    std::cout << std::left << std::setw(22) << "run" << std::setw(10) << "time s" << std::setw(10) << "speed-up"
              << std::setw(34) << "peak RSS per rank" << "TF bytes\n"
              << std::right;
    auto optimize_args = [&](const std::string& out, const std::string& summary) {
      std::vector<std::string> args{self_path(), "optimize", "--ref",  ref.string(),          "--field",
                                    field.string(), "--ref-tf", (work / "tf.json").string(), "--out", (work / out).string(),
                                    "--json",       (work / summary).string(), "--stream", "on", "-q"};
      if (!globals().device.empty()) args.insert(args.begin() + 1, {"--device", globals().device});
      return args;
    };
    const ChildRun plain = run_child(optimize_args("plain.json", "plain-summary.json"), work / "plain.log", "bench-mpi");
    if (plain.exit_code != 0)
      throw std::runtime_error("bench-mpi: tfmatch optimize exited with " + std::to_string(plain.exit_code) + ":\n" +
                               read_file(work / "plain.log"));
    const std::string plain_tf = read_file(work / "plain.json");
    std::cout << std::left << std::setw(22) << "without a launcher" << std::right << std::fixed << std::setprecision(2)
              << std::setw(6) << plain.seconds << "    " << std::setw(8) << "" << "  " << std::left << std::setw(34)
              << gib(plain.peak_rss_bytes) << "(reference)\n"
              << std::right << std::defaultfloat;
    rows.push_back({{"ranks", 0}, {"launcher", ""}, {"seconds", plain.seconds}, {"peak_rss_bytes", {plain.peak_rss_bytes}}});
    for (int r : a.ranks) {
      checkpoint("bench-mpi");
      std::vector<std::string> argv = launcher_words(a.launcher, r);
      const std::string out = "ranks" + std::to_string(r) + ".json", summary = "summary" + std::to_string(r) + ".json";
      for (const std::string& w : optimize_args(out, summary)) argv.push_back(w);
      // The launcher by name, as a shell would find it.
      if (argv.front().find('/') == std::string::npos) argv.insert(argv.begin(), {"/usr/bin/env"});
      const ChildRun run = run_child(argv, work / "mpi.log", "bench-mpi");
      if (run.exit_code != 0)
        throw std::runtime_error("bench-mpi: " + a.launcher + " with " + std::to_string(r) + " ranks exited with " +
                                 std::to_string(run.exit_code) + ":\n" + read_file(work / "mpi.log"));
      nlohmann::json s = nlohmann::json::parse(read_file(work / summary));
      std::vector<uint64_t> peaks;
      if (s.contains("stream") && s["stream"].contains("mpi_peak_rss_bytes"))
        peaks = s["stream"]["mpi_peak_rss_bytes"].get<std::vector<uint64_t>>();
      else
        peaks = {run.peak_rss_bytes};  // one rank: the largest process the launcher waited for
      const bool same = read_file(work / out) == plain_tf;
      std::ostringstream peak_text;
      peak_text << std::fixed << std::setprecision(2);
      for (size_t i = 0; i < peaks.size(); ++i) peak_text << (i ? " " : "") << double(peaks[i]) / double(1u << 30);
      peak_text << " GiB";
      std::cout << std::left << std::setw(22) << (std::to_string(r) + (r == 1 ? " rank" : " ranks")) << std::right
                << std::fixed << std::setprecision(2) << std::setw(6) << run.seconds << "    " << std::setw(8)
                << plain.seconds / run.seconds << "  " << std::left << std::setw(34)
                << peak_text.str() << (same ? "identical" : "DIFFERENT") << "\n"
                << std::right << std::defaultfloat;
      rows.push_back({{"ranks", r},
                      {"launcher", a.launcher},
                      {"seconds", run.seconds},
                      {"speedup_over_one_process", plain.seconds / run.seconds},
                      {"peak_rss_bytes", peaks},
                      {"tf_identical", same}});
      if (!same) throw std::runtime_error("bench-mpi: the TF of " + std::to_string(r) + " ranks differs from the run without a launcher");
    }
  }
  OutputBatch outputs;
  json.write({{"benchmark", "bench-mpi"},
              {"voxels", voxels},
              {"grid", d},
              {"cores", cores},
              {"load_average", load},
              {"runs", rows}});
  outputs.commit();
  return 0;
}

CommandRegistration reg(95, [](CLI::App& app) {
  auto args = std::make_shared<BenchMpiArgs>();
  auto* sub = app.add_subcommand("bench-mpi", "Benchmark: optimize --stream on split over MPI ranks (time, speed-up, "
                                 "peak memory per rank, identical TF) on a generated raw pair");
  sub->add_option("--voxels", args->voxels, "Voxels of the generated pair (grid x = y = 1.25 z)")
      ->check(CLI::Range(uint64_t(8), uint64_t(1) << 36))->capture_default_str();
  sub->add_option("--ranks", args->ranks, "Rank counts, comma separated")->delimiter(',')
      ->check(CLI::Range(1, 4096))->capture_default_str();
  sub->add_option("--launcher", args->launcher, "How to start R ranks, {ranks} replaced by R (e.g. 'srun -n {ranks}')")
      ->capture_default_str();
  sub->add_option("--dir", args->dir, "Where the files are written (default: the temporary directory); removed after");
  add_json_option(sub, args->json, "the measurements");
  sub->callback([args] { exit_code() = run(*args); });
});

}  // namespace
}  // namespace tfm::cli
