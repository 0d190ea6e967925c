// Every repository path that a comment, script or page names (`host/io/atomic_file.h`,
// `tests/kernels/test_render_gpu.cpp`) is a file of the repository. Files move between the
// layers' folders; a comment that still points to the old place sends the next reader nowhere
// (24 such references had piled up by 2026-12-04).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

namespace tfm {
namespace {

namespace fs = std::filesystem;

// The top-level folders a path can start with, and the kinds of file a reference names.
constexpr std::array<std::string_view, 8> kTopFolders{"engine", "kernels", "host", "shaders",
                                                      "tools",  "tests",   "docs", "cuda"};
constexpr std::array<std::string_view, 17> kNamedExtensions{".h",    ".cpp", ".c",  ".cu",   ".cuh",   ".comp",
                                                            ".glsl", ".md",  ".sh", ".py",   ".cmake", ".in",
                                                            ".txt",  ".mjs", ".js", ".html", ".css"};

bool ends_with(std::string_view s, std::string_view suffix) {
  return s.size() >= suffix.size() && s.substr(s.size() - suffix.size()) == suffix;
}

bool named_kind(std::string_view path) {
  return std::any_of(kNamedExtensions.begin(), kNamedExtensions.end(),
                     [&](std::string_view e) { return ends_with(path, e); });
}

bool path_char(char c) {
  return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.' || c == '/' || c == '-';
}

// The repository's text files (sources, scripts, pages), without build trees, installed packages
// and hidden folders other than .ci.
std::vector<fs::path> text_files(const fs::path& root) {
  std::vector<fs::path> files;
  for (auto it = fs::recursive_directory_iterator(root); it != fs::recursive_directory_iterator(); ++it) {
    const std::string name = it->path().filename().string();
    if (it->is_directory()) {
      const bool top = it->path().parent_path() == root;
      if ((name[0] == '.' && name != ".ci") || name == "node_modules" ||
          (top && (name.rfind("build", 0) == 0 || name.rfind("out", 0) == 0)))
        it.disable_recursion_pending();
      continue;
    }
    if (name != "package-lock.json" && (named_kind(name) || it->path().parent_path().filename() == ".ci"))
      files.push_back(it->path());
  }
  return files;
}

struct Reference {
  size_t line;
  std::string path;
};

// The paths `text` names: a top-level folder and '/' not inside a longer path (an install
// include such as <tfmatch/cuda/...>, ${CMAKE_CURRENT_SOURCE_DIR}/tools/...), extended over path
// characters, without a sentence's full stop, ending in a kind of file a reference names. Globs
// and folders end elsewhere and are not taken.
std::vector<Reference> named_paths(const std::string& text) {
  std::vector<Reference> refs;
  for (std::string_view top : kTopFolders) {
    const std::string start = std::string(top) + "/";
    for (size_t i = text.find(start); i != std::string::npos; i = text.find(start, i + 1)) {
      if (i > 0 && (path_char(text[i - 1]) || text[i - 1] == '$' || text[i - 1] == '}' || text[i - 1] == '<')) continue;
      size_t end = i + start.size();
      while (end < text.size() && path_char(text[end])) ++end;
      std::string path = text.substr(i, end - i);
      while (!path.empty() && path.back() == '.') path.pop_back();
      if (named_kind(path)) refs.push_back({size_t(std::count(text.begin(), text.begin() + i, '\n')) + 1, path});
    }
  }
  return refs;
}

std::string read_text(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  std::ostringstream os;
  os << in.rdbuf();
  return os.str();
}

TEST(SourcePaths, ReferencesFindTheirPathsAndNothingElse) {
  const std::string text =
      "// see host/io/atomic_file.h. Also (tests/kernels/test_render_gpu.cpp), `docs/solvers.md`\n"
      "#include <tfmatch/cuda/cuda_backend.h>\n"
      "${CMAKE_CURRENT_SOURCE_DIR}/tools/install_and_embed.cmake\n"
      "tests/engine/test_embedding_* and the folder host/io/ and myhost/x.h\n"
      "tools/cmake/tfmatchConfig.cmake.in\n";
  const std::vector<Reference> refs = named_paths(text);
  std::vector<std::string> paths;
  for (const Reference& r : refs) paths.push_back(std::to_string(r.line) + " " + r.path);
  std::sort(paths.begin(), paths.end());
  EXPECT_EQ(paths,
            (std::vector<std::string>{"1 docs/solvers.md", "1 host/io/atomic_file.h",
                                      "1 tests/kernels/test_render_gpu.cpp", "5 tools/cmake/tfmatchConfig.cmake.in"}));
}

TEST(SourcePaths, EveryNamedRepositoryFileExists) {
  const fs::path root = TFMATCH_SOURCE_DIR;
  size_t checked = 0;
  for (const fs::path& file : text_files(root))
    for (const Reference& ref : named_paths(read_text(file))) {
      ++checked;
      EXPECT_TRUE(fs::exists(root / ref.path))
          << fs::relative(file, root).generic_string() << ":" << ref.line << " names " << ref.path
          << ", which is not a file of the repository (moved? give its path now)";
    }
  // The comments, scripts and pages name several hundred files; far fewer means the scan broke.
  EXPECT_GT(checked, 300u);
}

}  // namespace
}  // namespace tfm
