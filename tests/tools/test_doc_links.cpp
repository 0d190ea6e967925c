// The documentation holds together: every relative link and picture in README.md and docs/*.md
// names a file of the repository (and, with #anchor, a heading of it), every docs page can be
// reached from the README, and every page starts by saying what it is for.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "doc_markdown.h"

namespace tfm {
namespace {

namespace fs = std::filesystem;
using test::DocPage;

std::map<std::string, DocPage> all_pages() {
  std::map<std::string, DocPage> pages;
  for (const std::string& p : test::doc_page_paths(TFMATCH_SOURCE_DIR)) pages.emplace(p, test::read_doc_page(TFMATCH_SOURCE_DIR, p));
  return pages;
}

bool external(const std::string& target) {
  return target.rfind("http://", 0) == 0 || target.rfind("https://", 0) == 0 || target.rfind("mailto:", 0) == 0;
}

// The page a relative link points to, relative to the repository root ("" for the same page).
std::string resolve(const std::string& page, const std::string& file_part) {
  if (file_part.empty()) return page;
  return (fs::path(page).parent_path() / file_part).lexically_normal().generic_string();
}

TEST(DocLinks, RelativeLinksAndAnchorsResolve) {
  const auto pages = all_pages();
  ASSERT_TRUE(pages.count("README.md"));
  size_t checked = 0;
  for (const auto& [path, page] : pages)
    for (const test::DocLink& link : page.links) {
      if (external(link.target)) continue;
      const size_t hash = link.target.find('#');
      const std::string file_part = link.target.substr(0, hash);
      const std::string target = resolve(path, file_part);
      ++checked;
      if (!fs::exists(fs::path(TFMATCH_SOURCE_DIR) / target)) {
        ADD_FAILURE() << path << ":" << link.line << ": link to " << link.target << ": " << target << " does not exist";
        continue;
      }
      if (hash == std::string::npos) continue;
      const std::string anchor = link.target.substr(hash + 1);
      const auto linked = pages.find(target);
      if (linked == pages.end()) continue;  // anchors are checked in the documentation's own pages
      EXPECT_TRUE(linked->second.anchors.count(anchor))
          << path << ":" << link.line << ": link to " << link.target << ": " << target << " has no heading #" << anchor;
    }
  EXPECT_GT(checked, 20u);
}

TEST(DocLinks, EveryDocsPageIsReachableFromTheReadme) {
  const auto pages = all_pages();
  std::set<std::string> reached{"README.md"};
  std::vector<std::string> todo{"README.md"};
  while (!todo.empty()) {
    const std::string path = todo.back();
    todo.pop_back();
    for (const test::DocLink& link : pages.at(path).links) {
      if (external(link.target)) continue;
      const std::string target = resolve(path, link.target.substr(0, link.target.find('#')));
      if (pages.count(target) && reached.insert(target).second) todo.push_back(target);
    }
  }
  for (const auto& [path, page] : pages) EXPECT_TRUE(reached.count(path)) << path << " cannot be reached from README.md";
}

// A page opens with its title and then a paragraph saying what it is for, before any section.
TEST(DocLinks, EveryDocsPageStartsWithWhatItIsFor) {
  for (const auto& [path, page] : all_pages()) {
    if (path == "README.md") continue;
    std::ifstream in(fs::path(TFMATCH_SOURCE_DIR) / path);
    std::string title, blank, first;
    std::getline(in, title);
    std::getline(in, blank);
    std::getline(in, first);
    EXPECT_EQ(title.rfind("# ", 0), 0u) << path << ": the first line is not the page's title";
    EXPECT_TRUE(blank.empty()) << path;
    EXPECT_FALSE(first.empty() || first[0] == '#' || first[0] == '`' || first[0] == '|' || first[0] == '!')
        << path << ": the title is not followed by a paragraph saying what the page is for";
  }
}

}  // namespace
}  // namespace tfm
