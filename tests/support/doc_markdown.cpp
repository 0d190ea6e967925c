// Markdown reading for the documentation tests (doc_markdown.h): only what the project's pages
// use — fences at the start of a line, inline links and images, ATX headings, HTML comments.
#include "doc_markdown.h"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>
#include <stdexcept>

namespace tfm::test {
namespace {

namespace fs = std::filesystem;

std::vector<std::string> words(const std::string& s) {
  std::istringstream in(s);
  std::vector<std::string> out;
  for (std::string w; in >> w;) out.push_back(w);
  return out;
}

// The line without its inline code spans (`...`), so that code is not read as links.
std::string without_code_spans(const std::string& line) {
  std::string out;
  bool in_code = false;
  for (char c : line) {
    if (c == '`') in_code = !in_code;
    else if (!in_code) out += c;
  }
  return out;
}

std::string trim(const std::string& s) {
  const size_t a = s.find_first_not_of(" \t");
  if (a == std::string::npos) return {};
  const size_t b = s.find_last_not_of(" \t\r");
  return s.substr(a, b - a + 1);
}

}  // namespace

bool DocBlock::has_word(const std::string& word) const {
  const auto w = words(info);
  return std::find(w.begin(), w.end(), word) != w.end();
}

std::string DocBlock::value(const std::string& key, bool* found) const {
  if (found) *found = false;
  for (const std::string& w : words(info)) {
    if (w == key) {
      if (found) *found = true;
      return {};
    }
    if (w.rfind(key + "=", 0) == 0) {
      if (found) *found = true;
      return w.substr(key.size() + 1);
    }
  }
  return {};
}

std::string heading_anchor(const std::string& heading) {
  std::string out;
  for (unsigned char c : heading) {
    if (std::isalnum(c)) out += char(std::tolower(c));
    else if (c == ' ') out += '-';
    else if (c == '-' || c == '_') out += char(c);
    else if (c >= 0x80) out += char(c);  // letters and symbols beyond ASCII stay
  }
  return out;
}

std::vector<std::string> doc_page_paths(const std::string& root) {
  std::vector<std::string> pages;
  if (fs::exists(fs::path(root) / "README.md")) pages.push_back("README.md");
  std::vector<std::string> docs;
  if (fs::is_directory(fs::path(root) / "docs"))
    for (const auto& e : fs::directory_iterator(fs::path(root) / "docs"))
      if (e.is_regular_file() && e.path().extension() == ".md") docs.push_back("docs/" + e.path().filename().string());
  std::sort(docs.begin(), docs.end());
  pages.insert(pages.end(), docs.begin(), docs.end());
  return pages;
}

DocPage read_doc_page(const std::string& root, const std::string& path) {
  std::ifstream in(fs::path(root) / path);
  if (!in) throw std::runtime_error("cannot read " + (fs::path(root) / path).string());
  DocPage page;
  page.path = path;
  static const std::regex link(R"(\[[^\]]*\]\(([^)\s]+)(\s+"[^"]*")?\))");
  static const std::regex image_marker(R"(<!--\s*doc-image:\s*(\S+)\s*->\s*(\S+)\s*-->)");
  std::map<std::string, int> anchor_uses;
  DocBlock* open = nullptr;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (open) {
      if (trim(line) == "```") open = nullptr;
      else open->lines.push_back(line);
      continue;
    }
    if (line.rfind("```", 0) == 0 && line.rfind("````", 0) != 0) {  // ```INFO (a longer run of ` is prose)
      page.blocks.push_back(DocBlock{path, number, trim(line.substr(3)), {}});
      open = &page.blocks.back();
      continue;
    }
    std::smatch m;
    if (std::regex_search(line, m, image_marker)) page.images.push_back(DocImage{path, number, m[1], m[2]});
    if (line.rfind("#", 0) == 0) {
      const size_t text = line.find_first_not_of('#');
      if (text != std::string::npos && line[text] == ' ') {
        const std::string base = heading_anchor(trim(line.substr(text)));
        const int uses = anchor_uses[base]++;
        page.anchors.insert(uses == 0 ? base : base + "-" + std::to_string(uses));
      }
    }
    const std::string prose = without_code_spans(line);
    for (auto it = std::sregex_iterator(prose.begin(), prose.end(), link); it != std::sregex_iterator(); ++it)
      page.links.push_back(DocLink{path, number, (*it)[1]});
  }
  if (open) throw std::runtime_error(path + ":" + std::to_string(open->line) + ": code block never closed");
  return page;
}

}  // namespace tfm::test
