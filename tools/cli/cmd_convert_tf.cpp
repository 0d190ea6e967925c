// `tfmatch convert-tf IN OUT`: transfer functions between tfmatch JSON, the framework's XML and
// ParaView presets (formats by content and extension, host/io/tf_formats.h).
#include <iostream>

#include "cli.h"
#include "output_options.h"
#include "tfmatch/io/output_check.h"
#include "tfmatch/io/tf_formats.h"
#include "tfmatch/model/builtin_tf.h"

namespace tfm::cli {
namespace {

struct ConvertTfArgs {
  std::string in, out;
  size_t size = 0;
};

int run(const ConvertTfArgs& a) {
  FilePlan().input_spec(a.in, "input").output(a.out, "output").check();
  std::vector<std::string> notes;
  TransferFunction tf = read_transfer_function(a.in, TfReadOptions{a.size, ""}, &notes);
  for (const auto& n : notes) print_note(n);
  write_transfer_function(a.out, tf);
  if (!globals().quiet) std::cout << "wrote " << a.out << " (" << tf.size() << " entries)\n";
  return 0;
}

CommandRegistration reg(40, [](CLI::App& app) {
  auto args = std::make_shared<ConvertTfArgs>();
  auto* sub = app.add_subcommand("convert-tf", "Convert a transfer function: .json (tfmatch), .xml (framework), .paraview.json");
  sub->add_option("in", args->in, "Input TF (tfmatch JSON, XML, ParaView preset; FILE:PRESET picks a preset), or a "
                  "built-in map to edit: " + builtin_tf_syntax())->required();
  sub->add_option("out", args->out, "Output TF; format from the extension")->required()
      ->check(output_format(transfer_function_format()));
  sub->add_option("--size", args->size, "Table entries when the input has control points (default: 256, or exact) or is a built-in map "
                  "(default: 64)")
      ->check(CLI::Range(size_t(2), size_t(1) << 16));
  sub->callback([args] { exit_code() = run(*args); });
});

}  // namespace
}  // namespace tfm::cli
