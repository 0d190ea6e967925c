// docs/commands.md and `tfmatch --help` cannot disagree: the reference holds, for the program and
// for every subcommand `tfmatch --help` lists, a ```text help=CMD block equal to the output of
// `tfmatch CMD --help`, and no block for a command the program does not have. The blocks are those
// of a build with the optional CUDA solvers; a build without them is compared with the blocks less
// the `cuda-*` entries. tools/gen-commands-md.sh rewrites the blocks from a build.
#include <gtest/gtest.h>

#include <filesystem>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "cli_runner.h"
#include "doc_markdown.h"

namespace tfm {
namespace {

namespace fs = std::filesystem;

// `tfmatch ARGS` as a user types it: found on PATH under its own name, so the usage lines say
// `tfmatch`, not the build's path.
std::string help_of(const std::string& args, int* exit_code) {
  static const test::TempDir bin;
  static const bool linked = [] {
    fs::create_symlink(fs::absolute(TFMATCH_CLI_PATH), bin.path / "tfmatch");
    return true;
  }();
  (void)linked;
  const std::string cmd = "PATH=\"" + bin.path.string() + ":$PATH\" tfmatch " + args + " 2>/dev/null";
  FILE* pipe = popen(cmd.c_str(), "r");
  std::string out;
  if (!pipe) return out;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof buf, pipe)) > 0) out.append(buf, n);
  const int status = pclose(pipe);
  *exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return out;
}

std::string without_trailing_newlines(std::string s) {
  while (!s.empty() && s.back() == '\n') s.pop_back();
  return s;
}

// The subcommands of `tfmatch --help`: the first word of each line of its subcommand list.
std::vector<std::string> subcommands(const std::string& help) {
  std::istringstream in(help);
  std::vector<std::string> out;
  bool in_list = false;
  for (std::string line; std::getline(in, line);) {
    if (line == "Subcommands:" || line == "SUBCOMMANDS:") {
      in_list = true;
      continue;
    }
    if (!in_list) continue;
    if (line.empty() || line[0] != ' ') break;
    std::istringstream words(line);
    std::string name;
    words >> name;
    if (!name.empty()) out.push_back(name);
  }
  return out;
}

// The documented help as a build without the optional CUDA solvers prints it: the blocks are
// those of a build with them (docs/commands.md says so), which list `cuda-cgls` and
// `cuda-normal-equations` among the solvers and describe each in the solver list.
std::string without_cuda_solvers(const std::string& text) {
  std::istringstream in(text);
  std::string out, line;
  bool in_entry = false;
  while (std::getline(in, line)) {
    if (line.rfind("  cuda-", 0) == 0) {
      in_entry = true;  // a solver's entry: its line and the more indented lines under it
      continue;
    }
    if (in_entry && line.rfind("      ", 0) == 0) continue;
    in_entry = false;
    for (const std::string name : {", cuda-cgls", ", cuda-normal-equations"})
      for (size_t p; (p = line.find(name)) != std::string::npos;) line.erase(p, name.size());
    out += line + "\n";
  }
  return out;
}

// First differing line of two texts, for the failure message.
std::string first_difference(const std::string& doc, const std::string& program) {
  std::istringstream a(doc), b(program);
  std::string la, lb;
  for (int line = 1;; ++line) {
    const bool ha = bool(std::getline(a, la)), hb = bool(std::getline(b, lb));
    if (!ha && !hb) return "none";
    if (!ha || !hb || la != lb)
      return "line " + std::to_string(line) + " of the block:\n  commands.md: " + (ha ? la : "(ends)") +
             "\n  --help:      " + (hb ? lb : "(ends)");
  }
}

TEST(DocCommands, ReferenceMatchesHelpOfEverySubcommand) {
  const test::DocPage page = test::read_doc_page(TFMATCH_SOURCE_DIR, "docs/commands.md");
  std::map<std::string, const test::DocBlock*> blocks;  // "" for `tfmatch --help`
  for (const test::DocBlock& b : page.blocks) {
    bool found = false;
    const std::string cmd = b.value("help", &found);
    if (!found) continue;
    EXPECT_TRUE(blocks.emplace(cmd, &b).second) << "docs/commands.md:" << b.line << ": a second help block for '" << cmd << "'";
  }
  int code = -1;
  const std::string top = help_of("--help", &code);
  ASSERT_EQ(code, 0) << top;
  const std::vector<std::string> commands = subcommands(top);
  ASSERT_GE(commands.size(), 10u) << "no subcommand list found in tfmatch --help:\n" << top;

  const std::string regenerate = "\n(tools/gen-commands-md.sh rewrites the help blocks from build/tfmatch)";
  // A build without the CUDA solvers is compared with the blocks less their entries.
  const bool cuda = help_of("optimize --help", &code).find("cuda-cgls") != std::string::npos;
  std::vector<std::string> all{""};
  all.insert(all.end(), commands.begin(), commands.end());
  for (const std::string& cmd : all) {
    const std::string shown = cmd.empty() ? "tfmatch --help" : "tfmatch " + cmd + " --help";
    const auto it = blocks.find(cmd);
    if (it == blocks.end()) {
      ADD_FAILURE() << "docs/commands.md has no ```text help" << (cmd.empty() ? "" : "=" + cmd) << " block for `" << shown
                    << "`" << regenerate;
      continue;
    }
    const std::string help = cmd.empty() ? top : help_of(cmd + " --help", &code);
    EXPECT_EQ(code, 0) << shown;
    std::string doc;
    for (const std::string& l : it->second->lines) doc += l + "\n";
    if (!cuda) doc = without_cuda_solvers(doc);
    EXPECT_TRUE(without_trailing_newlines(doc) == without_trailing_newlines(help))
        << "docs/commands.md:" << it->second->line << ": the block differs from `" << shown << "` at "
        << first_difference(doc, help) << regenerate;
  }
  const std::set<std::string> known(all.begin(), all.end());
  for (const auto& [cmd, block] : blocks)
    EXPECT_TRUE(known.count(cmd)) << "docs/commands.md:" << block->line << ": tfmatch has no subcommand '" << cmd << "'";
}

}  // namespace
}  // namespace tfm
