// `tfmatch info FILE...`: what each file holds (variables or arrays, grids, types, ranges, NaN
// counts) and how to name each one on the command line.
#include <iostream>

#include "cli.h"
#include "volume_format_table.h"
#include "volume_info.h"
#include "volume_io.h"

namespace tfm::cli {
namespace {

struct InfoArgs {
  std::vector<std::string> files;
  bool json = false;
  std::vector<uint64_t> dims;
  std::string type;
  bool big_endian = false;
};

int run(const InfoArgs& a) {
  VolumeOptions vo;
  if (!a.dims.empty()) vo.dims = std::array<uint64_t, 3>{a.dims[0], a.dims[1], a.dims[2]};
  if (!a.type.empty()) {
    vo.type = parse_scalar_type(a.type);
    if (vo.type == ScalarType::Unknown) throw std::runtime_error("--type: unknown element type '" + a.type + "'");
  }
  vo.big_endian = a.big_endian;
  nlohmann::json all = nlohmann::json::array();
  for (const auto& f : a.files) {
    FileInfo info = describe_file(f, vo);
    if (a.json) all.push_back(file_info_json(info));
    else std::cout << format_file_info(info) << (a.files.size() > 1 ? "\n" : "");
  }
  if (a.json) std::cout << (a.files.size() == 1 ? all[0] : all).dump(2) << "\n";
  return 0;
}

CommandRegistration reg(30, [](CLI::App& app) {
  auto args = std::make_shared<InfoArgs>();
  auto* sub = app.add_subcommand("info", "List what data files hold: variables/arrays, grids, types, ranges, NaN counts");
  sub->add_option("files", args->files, volume_format_titles(nullptr, " or ") + " files")->required();
  sub->add_flag("--json", args->json, "Print JSON instead of text");
  sub->add_option("--dims", args->dims, "Raw files: grid size X,Y,Z")->expected(3)->delimiter(',')
      ->check(positive_integer());
  sub->add_option("--type", args->type, "Raw files: element type (uint8, uint16, int16, float32, float64, ...)");
  sub->add_flag("--big-endian", args->big_endian, "Raw files: big-endian data");
  sub->footer("Formats (by extension, else by the first bytes):\n" + volume_format_help());
  sub->callback([args] { exit_code() = run(*args); });
});

}  // namespace
}  // namespace tfm::cli
