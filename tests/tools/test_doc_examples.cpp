// The documentation's examples run as written. Every code block of README.md and docs/*.md whose
// info string says `runnable` (```sh runnable) is run by bash, the blocks of one page in order in
// one shell and one fresh directory, as a reader following the page would: `tfmatch` is this
// build's program (first on PATH) and $DATA the shared real data (../shared/data). Each command
// must exit 0, and every file it says it writes (--out, --report, --json, --image, -o; the output
// of convert-tf and convert-volume) must exist afterwards. A page whose examples use $DATA is
// skipped, saying so, when the shared data are absent.
//
// Pictures: a page's `<!-- doc-image: SRC -> DEST -->` lines name a file its examples write (SRC)
// and the picture the page shows (DEST, relative to the page). SRC must be written; with
// TFMATCH_UPDATE_DOC_IMAGES=1 the test copies it over DEST in the source tree, so the pictures in
// the documentation are those of the commands beside them.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cctype>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "cli_runner.h"
#include "doc_markdown.h"
#include "vk_test_env.h"

namespace tfm {
namespace {

namespace fs = std::filesystem;
using test::DocBlock;
using test::DocPage;

// Pages with at least one runnable block (the test's parameters).
std::vector<std::string> pages_with_examples() {
  std::vector<std::string> out;
  for (const std::string& p : test::doc_page_paths(TFMATCH_SOURCE_DIR)) {
    try {
      const DocPage page = test::read_doc_page(TFMATCH_SOURCE_DIR, p);
      for (const DocBlock& b : page.blocks)
        if (b.has_word("runnable")) {
          out.push_back(p);
          break;
        }
    } catch (const std::exception&) {
      out.push_back(p);  // the page's test reports what is wrong with it
    }
  }
  return out;
}

bool uses_shared_data(const DocBlock& b) {
  for (const std::string& l : b.lines)
    if (l.find("$DATA") != std::string::npos || l.find("${DATA}") != std::string::npos) return true;
  return false;
}

// Words of a command line as the shell would split a simple one: quotes removed, a comment ends it.
std::vector<std::string> shell_words(const std::string& line) {
  std::vector<std::string> out;
  std::string w;
  bool have = false;
  char quote = 0;
  for (char c : line) {
    if (quote) {
      if (c == quote) quote = 0;
      else w += c;
    } else if (c == '\'' || c == '"') {
      quote = c, have = true;
    } else if (c == ' ' || c == '\t') {
      if (have) out.push_back(w);
      w.clear(), have = false;
    } else if (c == '#' && !have) {
      break;
    } else {
      w += c, have = true;
    }
  }
  if (have) out.push_back(w);
  return out;
}

bool has_suffix(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// The files a command line says it writes: values of the output options of each `tfmatch`
// command in it (for optimize with several fields, the first indexed TF and the series table),
// and the last file name of convert-tf / convert-volume.
std::vector<std::string> declared_outputs(const std::string& command) {
  static const std::vector<std::string> options{"--out", "--report", "--json", "--image", "-o"};
  const std::vector<std::string> w = shell_words(command);
  std::vector<std::string> out;
  for (size_t i = 0; i < w.size(); ++i) {
    if (w[i] != "tfmatch") continue;
    size_t end = i + 1;
    while (end < w.size() && w[end] != "&&" && w[end] != "||" && w[end] != ";" && w[end] != "|") ++end;
    const std::string sub = i + 1 < end ? w[i + 1] : "";
    // optimize with several fields writes --out with an index per field (t.json -> t_000.json, ...)
    // unless --shared-tf, and the series table <stem>_series.csv either way.
    size_t fields = 0;
    bool shared = false;
    for (size_t k = i + 1; k < end; ++k) {
      if (w[k] == "--field" && k + 1 < end)
        fields += w[k + 1].find("..") != std::string::npos || w[k + 1].find_first_of("*?[") != std::string::npos ? 2 : 1;
      shared = shared || w[k] == "--shared-tf";
    }
    const bool series = sub == "optimize" && fields > 1;
    std::string converted;
    for (size_t k = i + 1; k < end; ++k) {
      if (series && w[k] == "--out" && k + 1 < end) {
        const std::string& o = w[k + 1];
        const size_t dot = o.rfind('.'), stem_end = o.find('.', o.rfind('/') == std::string::npos ? 0 : o.rfind('/'));
        out.push_back(shared ? o : o.substr(0, dot) + "_000" + o.substr(dot));
        out.push_back(o.substr(0, stem_end) + "_series.csv");
        continue;
      }
      for (const std::string& o : options) {
        if (w[k] == o && k + 1 < end && w[k + 1] != "-") out.push_back(w[k + 1]);
        if (w[k].rfind(o + "=", 0) == 0 && w[k].size() > o.size() + 1 && w[k].substr(o.size() + 1) != "-")
          out.push_back(w[k].substr(o.size() + 1));
      }
      for (const char* ext : {".vti", ".raw", ".json", ".xml"})
        if (k > i + 2 && w[k][0] != '-' && has_suffix(w[k], ext)) converted = w[k];
    }
    if ((sub == "convert-tf" || sub == "convert-volume") && !converted.empty()) out.push_back(converted);
    i = end;
  }
  return out;
}

std::string quoted_for_double_quotes(const std::string& s) {
  std::string out;
  for (char c : s) {
    if (c == '"' || c == '\\' || c == '`') out += '\\';
    out += c;
  }
  return out;
}

// One bash script running the page's runnable blocks in order; after each command, a check
// that the files it names as outputs exist (in the script, so $VARIABLES expand as they did).
std::string page_script(const DocPage& page, const fs::path& workdir, int* commands) {
  std::ostringstream s;
  s << "set -eo pipefail\n"
    << "doc_where=\n"
    << "trap 'echo \"doc example failed: $doc_where: $BASH_COMMAND (exit $?)\" >&2' ERR\n"
    << "cd \"" << quoted_for_double_quotes(workdir.string()) << "\"\n";
  static const std::regex heredoc(R"(<<(-?)\s*(['"]?)([A-Za-z_][A-Za-z0-9_]*)\2)");
  for (const DocBlock& b : page.blocks) {
    if (!b.has_word("runnable")) continue;
    for (size_t i = 0; i < b.lines.size(); ++i) {
      const int line = b.line + 1 + int(i);
      std::string logical = b.lines[i];
      std::vector<std::string> text{b.lines[i]};
      // Continuation lines belong to the same command.
      while (!logical.empty() && logical.back() == '\\' && i + 1 < b.lines.size()) {
        logical.pop_back();
        logical += " " + b.lines[++i];
        text.push_back(b.lines[i]);
      }
      std::smatch m;
      if (std::regex_search(logical, m, heredoc)) {  // the here-document's body, verbatim
        const bool strip_tabs = m[1] == "-";
        const std::string end = m[3];
        while (i + 1 < b.lines.size()) {
          const std::string body = b.lines[++i];
          text.push_back(body);
          std::string cmp = body;
          if (strip_tabs) cmp.erase(0, cmp.find_first_not_of('\t'));
          if (cmp == end) break;
        }
      }
      const std::string where = page.path + ":" + std::to_string(line);
      s << "doc_where=" << where << "\n";
      for (const std::string& t : text) s << t << "\n";
      const std::vector<std::string> outputs = declared_outputs(logical);
      for (const std::string& w : shell_words(logical)) *commands += w == "tfmatch";
      for (const std::string& o : outputs)
        s << "[ -e \"" << quoted_for_double_quotes(o) << "\" ] || { echo \"" << where << ": the command says it writes "
          << quoted_for_double_quotes(o) << ", which does not exist\" >&2; exit 97; }\n";
    }
  }
  s << "doc_where=end\n";
  return s.str();
}

std::string read_file(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

class DocExamples : public testing::TestWithParam<std::string> {};

TEST_P(DocExamples, RunAsWritten) {
  const DocPage page = test::read_doc_page(TFMATCH_SOURCE_DIR, GetParam());
  const std::string data = test::shared_data_dir();
  if (data.empty()) {
    std::string needing;
    for (const DocBlock& b : page.blocks)
      if (b.has_word("runnable") && uses_shared_data(b)) needing += " " + page.path + ":" + std::to_string(b.line);
    if (!needing.empty())
      GTEST_SKIP() << "examples need the shared data (../shared/data, or TFMATCH_SHARED_DATA), absent here:" << needing;
  }
  test::TempDir dir;
  const fs::path bin = dir.path / "bin", work = dir.path / "work";
  fs::create_directories(bin);
  fs::create_directories(work);
  fs::create_symlink(fs::absolute(TFMATCH_CLI_PATH), bin / "tfmatch");
  int commands = 0;
  const std::string script = page_script(page, work, &commands);
  std::ofstream(dir.path / "examples.sh") << script;
  const std::string env = "PATH=\"" + bin.string() + ":$PATH\" DATA=\"" + (data.empty() ? "/nonexistent" : fs::absolute(data).string()) + "\"";
  const std::string cmd = env + " bash \"" + (dir.path / "examples.sh").string() + "\" > \"" + (dir.path / "log").string() + "\" 2>&1";
  const int status = std::system(cmd.c_str());
  const int code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  ASSERT_EQ(code, 0) << "the examples of " << page.path << " failed (exit " << code << "):\n"
                     << read_file(dir.path / "log") << "\nscript:\n" << script;
  std::cout << page.path << ": " << commands << " tfmatch commands ran\n";

  const bool update = std::getenv("TFMATCH_UPDATE_DOC_IMAGES") && std::string(std::getenv("TFMATCH_UPDATE_DOC_IMAGES")) == "1";
  for (const test::DocImage& image : page.images) {
    const fs::path produced = work / image.source;
    const fs::path shown = (fs::path(TFMATCH_SOURCE_DIR) / page.path).parent_path() / image.dest;
    ASSERT_TRUE(fs::exists(produced)) << page.path << ":" << image.line << ": the examples did not write " << image.source;
    if (update) {
      fs::copy_file(produced, shown, fs::copy_options::overwrite_existing);
      std::cout << "updated " << fs::path(shown).lexically_normal().string() << " from " << image.source << "\n";
    } else {
      EXPECT_TRUE(fs::exists(shown)) << page.path << ":" << image.line << ": " << image.dest
                                     << " is missing (TFMATCH_UPDATE_DOC_IMAGES=1 writes it)";
    }
  }
}

std::string page_test_name(const testing::TestParamInfo<std::string>& info) {
  std::string name;
  for (char c : info.param) name += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
  return name;
}

INSTANTIATE_TEST_SUITE_P(Docs, DocExamples, testing::ValuesIn(pages_with_examples()), page_test_name);

// How the examples are found: a block is runnable only when its info string says so; the words
// that mark outputs are read as the shell would.
TEST(DocExamplesParsing, OutputsOfACommandLine) {
  EXPECT_EQ(declared_outputs("tfmatch optimize --ref a --out v.json --report r --json - # --out x"),
            (std::vector<std::string>{"v.json", "r"}));
  EXPECT_EQ(declared_outputs("tfmatch selftest --json=s.json"), (std::vector<std::string>{"s.json"}));
  EXPECT_EQ(declared_outputs("tfmatch convert-tf viridis my.json"), (std::vector<std::string>{"my.json"}));
  EXPECT_EQ(declared_outputs("tfmatch convert-volume \"$D/a.nc:U\" b.nc:V w.vti --var U"),
            (std::vector<std::string>{"w.vti"}));
  EXPECT_EQ(declared_outputs("E=x.grib:t"), (std::vector<std::string>{}));
  EXPECT_EQ(declared_outputs("tfmatch residual --image r.png --out m.raw && tfmatch render --out x.png"),
            (std::vector<std::string>{"r.png", "m.raw", "x.png"}));
}

TEST(DocExamplesParsing, EveryRunnableBlockIsShellAndCounted) {
  int blocks = 0, commands = 0;
  for (const std::string& p : test::doc_page_paths(TFMATCH_SOURCE_DIR)) {
    const DocPage page = test::read_doc_page(TFMATCH_SOURCE_DIR, p);
    for (const DocBlock& b : page.blocks) {
      if (!b.has_word("runnable")) continue;
      ++blocks;
      EXPECT_EQ(b.info.rfind("sh ", 0), 0u) << p << ":" << b.line << ": a runnable block is a shell block (```sh runnable)";
    }
    page_script(page, "/tmp", &commands);
  }
  std::cout << blocks << " runnable blocks, " << commands << " tfmatch commands\n";
  EXPECT_GT(blocks, 0);
}

}  // namespace
}  // namespace tfm
