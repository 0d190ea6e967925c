// `tfmatch info FILE...`: what each file holds (variables or arrays, grids, types, ranges, NaN
// counts) and how to name each one on the command line; with a selection (FILE:VAR,... or --var,
// --time, --member), the field as loaded at that time and member.
#include <iostream>

#include "cli.h"
#include "input_options.h"
#include "output_options.h"
#include "tfmatch/io/output_check.h"
#include "tfmatch/io/volume_format_table.h"
#include "tfmatch/io/volume_info.h"
#include "tfmatch/io/volume_io.h"

namespace tfm::cli {
namespace {

struct InfoArgs {
  std::vector<std::string> files;
  std::string json;
  VolumeFlags volume_flags;  // raw layout; --var, --time, --member select one field
};

// A spec names a selection when it is not an existing file (FILE:VAR,...) or a selector is given.
bool is_selection(const std::string& spec, const VolumeFlags& flags) {
  std::error_code ec;
  return flags.selects() || (!std::filesystem::exists(spec, ec) && spec.find(':') != std::string::npos);
}

int run(const InfoArgs& a) {
  const JsonOutput json(a.json);  // first: with '-', stdout holds only the JSON
  FilePlan files;
  for (const auto& f : a.files) files.input_spec(f, "input");
  files.output(json.file(), "--json").check();
  const VolumeOptions vo = a.volume_flags.options(a.files);
  nlohmann::json all = nlohmann::json::array();
  for (const auto& f : a.files) {
    const FileInfo info = is_selection(f, a.volume_flags) ? describe_selection(f, vo) : describe_file(f, vo);
    all.push_back(file_info_json(info));
    std::cout << format_file_info(info) << (a.files.size() > 1 ? "\n" : "");
  }
  json.write(a.files.size() == 1 ? all[0] : all);
  return 0;
}

CommandRegistration reg(30, [](CLI::App& app) {
  auto args = std::make_shared<InfoArgs>();
  auto* sub = app.add_subcommand("info", "List what data files hold: variables/arrays, grids, types, ranges, NaN counts");
  sub->add_option("files", args->files, volume_format_titles(nullptr, " or ") +
                  " files; FILE:VAR[,time=N][,member=N] (or --var, --time, --member) describes that field as loaded")
      ->required();
  add_json_option(sub, args->json, "the description");
  add_volume_flags(sub, args->volume_flags);
  sub->footer("Formats (by extension, else by the first bytes):\n" + volume_format_help());
  sub->callback([args] { exit_code() = run(*args); });
});

}  // namespace
}  // namespace tfm::cli
