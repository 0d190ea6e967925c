// `tfmatch convert-volume IN... OUT.vti`: any field tfmatch reads, as VTK ImageData for ParaView.
#include <algorithm>
#include <filesystem>
#include <iostream>
#include <set>

#include "cli.h"
#include "input_options.h"
#include "output_options.h"
#include "tfmatch/io/atomic_file.h"
#include "tfmatch/io/output_check.h"
#include "tfmatch/io/volume_format_table.h"
#include "tfmatch/io/volume_formats.h"
#include "tfmatch/io/volume_io.h"
#include "tfmatch/io/volume_vti.h"

namespace tfm::cli {
namespace {

struct ConvertVolumeArgs {
  std::vector<std::string> inputs;
  std::string out;
  VolumeFlags volume_flags;  // raw layout, --var, --time, --member
  bool no_compress = false;
};

int run(const ConvertVolumeArgs& a) {
  check_output_format(a.out, vti_format(), "output");
  FilePlan files;
  for (size_t i = 0; i < a.inputs.size(); ++i) files.input_spec(a.inputs[i], "input " + std::to_string(i + 1));
  files.output(a.out, "output").check();
  OutputBatch outputs;
  const VolumeOptions vo = a.volume_flags.options(a.inputs);
  std::vector<Volume> volumes;
  std::vector<std::pair<std::string, const Volume*>> arrays;
  volumes.reserve(a.inputs.size());
  for (const auto& in : a.inputs) {
    volumes.push_back(load_volume(in, vo));
    if (volumes.size() > 1) require_same_grid(volumes.front(), volumes.back());
  }
  // Array names: the variable after the last ':' without its ",time=N"-style selectors (a name
  // with them could not be selected, `FILE:A,time=1` being a selector itself), else the file
  // stem. One variable given at several times or members is named by them ("T_time0",
  // "T_time3": a bare "T_2" read as time 2 in ParaView); what is still taken (two files of one
  // name in different folders) gets _2, _3, ..., so that each array can be selected by its name.
  std::vector<std::string> names, selections;
  for (size_t i = 0; i < volumes.size(); ++i) {
    const std::string& n = volumes[i].name;
    const auto colon = n.rfind(':');
    std::string name = colon != std::string::npos ? n.substr(colon + 1) : std::filesystem::path(n).stem().string();
    std::string selection;  // "time3_member1" from ",time=3,member=1": the name's, else as given
    auto selectors = [](const std::string& spec_part) {
      std::string s;
      for (char c : spec_part.substr(std::min(spec_part.find(','), spec_part.size())))
        if (c != '=') s += c == ',' ? '_' : c;
      return s.empty() ? s : s.substr(1);
    };
    if (colon != std::string::npos) {
      selection = selectors(name);
      name = name.substr(0, name.find(','));
    }
    if (selection.empty()) {
      const std::string& spec = a.inputs[i];
      const auto spec_colon = spec.rfind(':');
      if (spec_colon != std::string::npos) selection = selectors(spec.substr(spec_colon + 1));
    }
    names.push_back(name.empty() ? "field" + std::to_string(i) : name);
    selections.push_back(selection);
  }
  std::set<std::string> taken;
  for (size_t i = 0; i < volumes.size(); ++i) {
    std::string name = names[i];
    if (std::count(names.begin(), names.end(), names[i]) > 1 && !selections[i].empty()) name += "_" + selections[i];
    std::string unique = name;
    for (int k = 2; taken.count(unique); ++k) unique = name + "_" + std::to_string(k);
    taken.insert(unique);
    arrays.emplace_back(unique, &volumes[i]);
  }
  write_vti(a.out, arrays, VtiWriteOptions{!a.no_compress});
  outputs.commit();
  if (!globals().quiet) {
    std::cout << "wrote " << a.out << " (" << arrays.size() << " array(s) of Float32:";
    for (const auto& [name, v] : arrays) std::cout << " " << name;
    std::cout << ")\n";
  }
  return 0;
}

CommandRegistration reg(41, [](CLI::App& app) {
  auto args = std::make_shared<ConvertVolumeArgs>();
  auto* sub = app.add_subcommand("convert-volume", "Write fields (same grid) as one .vti for ParaView");
  sub->add_option("inputs", args->inputs, "Fields (file or file:VARIABLE), then the output .vti. Every array is written "
                  "as Float32, the values as tfmatch loads them (float64 rounded to float32, a vector array as its "
                  "magnitude)")->required()->expected(2, -1);
  add_volume_flags(sub, args->volume_flags);
  sub->add_flag("--no-compress", args->no_compress, "Write raw instead of zlib-compressed data");
  sub->callback([args] {
    args->out = args->inputs.back();
    args->inputs.pop_back();
    exit_code() = run(*args);
  });
});

}  // namespace
}  // namespace tfm::cli
