// The `tfmatch` program: parses the command line and runs the chosen subcommand.
#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <exception>
#include <iostream>
#include <sstream>
#include <string_view>

#include "cli.h"
#include "tfmatch_version.h"  // generated in the build directory (top-level CMakeLists.txt)
#include "vk_check.h"

namespace tfm::cli {

GlobalOptions& globals() {
  static GlobalOptions g;
  return g;
}

std::vector<std::pair<int, CommandSetup>>& registered_commands() {
  static std::vector<std::pair<int, CommandSetup>> list;
  return list;
}

CommandRegistration::CommandRegistration(int order, CommandSetup setup) {
  registered_commands().emplace_back(order, std::move(setup));
}

int& exit_code() {
  static int code = 0;
  return code;
}

// Set when a context reported validation messages: the run is then a failure (exit code 3),
// whatever the command returned.
static bool& validation_failed() {
  static bool failed = false;
  return failed;
}

std::shared_ptr<Context> make_context(bool validation_when_installed) {
  ContextOptions options;
  const std::string& d = globals().device;
  if (!d.empty()) {
    if (std::all_of(d.begin(), d.end(), ::isdigit)) options.device_index = std::stoul(d);
    else options.device_name = d;
  }
  if (globals().validation) {
    options.validation = true;
    options.require_validation = true;
  } else if (validation_when_installed) {
    options.validation = true;
  }
  return std::shared_ptr<Context>(Context::create(options).release(), [](Context* ctx) {
    auto messages = ctx->take_validation_messages();
    for (const std::string& m : messages) std::cerr << "tfmatch: Vulkan validation " << m << "\n";
    if (!messages.empty()) validation_failed() = true;
    delete ctx;
  });
}

FieldRange parse_range(const std::string& text, const std::string& flag) {
  auto comma = text.find(',');
  try {
    if (comma == std::string::npos) throw std::invalid_argument("no comma");
    size_t used = 0;
    FieldRange r{std::stod(text.substr(0, comma), &used), 0.0};
    if (used != comma) throw std::invalid_argument("junk");
    std::string rest = text.substr(comma + 1);
    r.hi = std::stod(rest, &used);
    if (used != rest.size()) throw std::invalid_argument("junk");
    return r;
  } catch (const std::exception&) {
    throw CLI::ValidationError(flag, "expected lo,hi (two numbers), got '" + text + "'");
  }
}

std::string version_text() {
  std::ostringstream os;
  os << "tfmatch " << TFMATCH_VERSION << "\n"
     << "commit: " << TFMATCH_GIT_COMMIT << "\n"
     << "build type: " << TFMATCH_BUILD_TYPE << "\n"
     << "Vulkan headers: " << VK_API_VERSION_MAJOR(VK_HEADER_VERSION_COMPLETE) << "."
     << VK_API_VERSION_MINOR(VK_HEADER_VERSION_COMPLETE) << "." << VK_HEADER_VERSION << "\n"
     << "compiler: " << TFMATCH_COMPILER;
  return os.str();
}

std::string version_line() { return std::string("tfmatch ") + TFMATCH_VERSION + " (commit " + TFMATCH_GIT_COMMIT + ")"; }

// argv as a shell would need it typed: words with anything but [A-Za-z0-9_./:=,+-@%] single-quoted.
static std::string quoted_command_line(int argc, char** argv) {
  std::string out;
  for (int i = 0; i < argc; ++i) {
    const std::string w = argv[i];
    const bool plain = !w.empty() && std::all_of(w.begin(), w.end(), [](char c) {
      return std::isalnum(static_cast<unsigned char>(c)) || std::string_view("_./:=,+-@%").find(c) != std::string_view::npos;
    });
    std::string q = "'";
    for (char c : w) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
    out += (i ? " " : "") + (plain ? w : q + "'");
  }
  return out;
}

}  // namespace tfm::cli

int main(int argc, char** argv) {
  using namespace tfm::cli;
  globals().command_line = quoted_command_line(argc, argv);
  CLI::App app{"tfmatch: optimize a transfer function so a second field's volume renderings match a reference's"};
  app.require_subcommand(1);
  app.set_help_all_flag("--help-all", "Print help for every subcommand");
  app.set_version_flag("--version", version_text(), "Print the version, git commit, build type, Vulkan headers and compiler");
  app.add_option("--device", globals().device, "Vulkan device: index or name substring (env TFMATCH_DEVICE)");
  app.add_flag("--validation", globals().validation, "Enable the Khronos validation layer (env TFMATCH_VALIDATION=1)");
  app.add_flag("-q,--quiet", globals().quiet, "Print only errors");
  auto& commands = registered_commands();
  std::sort(commands.begin(), commands.end(), [](auto& a, auto& b) { return a.first < b.first; });
  for (auto& [order, setup] : commands) setup(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const tfm::VulkanError& e) {
    std::cerr << "tfmatch: Vulkan error: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "tfmatch: error: " << e.what() << "\n";
    return 1;
  }
  if (validation_failed()) return 3;
  return exit_code();
}
