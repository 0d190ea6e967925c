// Reads the project's Markdown documentation (README.md and docs/*.md) the way the documentation
// tests need it: fenced code blocks with their info strings, relative links, heading anchors and
// the `<!-- doc-image: SRC -> DEST -->` markers of pictures a page's examples produce.
#pragma once

#include <set>
#include <string>
#include <vector>

namespace tfm::test {

// A fenced code block: ```INFO ... ```.
struct DocBlock {
  std::string page;                // path relative to the repository root, e.g. "docs/solvers.md"
  int line = 0;                    // 1-based line of the opening fence
  std::string info;                // the info string after the fence ("sh runnable", "text help=info")
  std::vector<std::string> lines;  // the block's lines, without the fences
  // Whether the info string has the word `word` ("runnable" in "sh runnable").
  bool has_word(const std::string& word) const;
  // The value of `key=VALUE` in the info string; `found` says whether the key (or the bare word
  // `key`) is there at all.
  std::string value(const std::string& key, bool* found = nullptr) const;
};

// A link or image `[text](target)` outside code.
struct DocLink {
  std::string page;
  int line = 0;
  std::string target;  // as written, anchor included
};

// `<!-- doc-image: SRC -> DEST -->`: the page's examples write SRC (relative to the directory
// they run in); DEST is the picture the page shows (relative to the page's directory).
struct DocImage {
  std::string page;
  int line = 0;
  std::string source, dest;
};

struct DocPage {
  std::string path;  // relative to the repository root
  std::vector<DocBlock> blocks;
  std::vector<DocLink> links;
  std::vector<DocImage> images;
  std::set<std::string> anchors;  // GitHub's anchors of the page's headings
};

// README.md and every docs/*.md under `root`, README first, then by name.
std::vector<std::string> doc_page_paths(const std::string& root);
// Parses one page (`path` relative to `root`). Throws std::runtime_error when it cannot be read.
DocPage read_doc_page(const std::string& root, const std::string& path);

// GitHub's anchor for a heading's text: lower case, spaces to '-', punctuation other than '-'
// and '_' dropped (inline code marks too), other characters kept.
std::string heading_anchor(const std::string& heading);

}  // namespace tfm::test
