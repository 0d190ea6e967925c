// The viewer page, assembled from its three files.
#include "view_page.h"

#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string_view>

#include "view_page_assets.h"  // generated at build time from host/viewer/page (tools/cmake/embed_files.cmake)

namespace tfm {
namespace {

std::string read_asset(const std::string& dir, const char* name) {
  const std::filesystem::path path = std::filesystem::path(dir) / name;
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error(path.string() + ": cannot read the viewer page file");
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

// `html` with the line holding `marker` replaced by `replacement` (the whole line).
std::string replace_line(std::string html, std::string_view marker, const std::string& replacement) {
  const size_t at = html.find(marker);
  if (at == std::string::npos) throw std::runtime_error("viewer page: index.html lacks the line " + std::string(marker));
  const size_t begin = html.rfind('\n', at) == std::string::npos ? 0 : html.rfind('\n', at) + 1;
  size_t end = html.find('\n', at);
  if (end == std::string::npos) end = html.size();
  return html.replace(begin, end - begin, replacement);
}

}  // namespace

std::string view_page_html(const std::string& assets_dir) {
  std::string html, css, js;
  if (assets_dir.empty()) {
    html = std::string(view_asset_index_html());
    css = std::string(view_asset_viewer_css());
    js = std::string(view_asset_viewer_js());
  } else {
    html = read_asset(assets_dir, "index.html");
    css = read_asset(assets_dir, "viewer.css");
    js = read_asset(assets_dir, "viewer.js");
  }
  html = replace_line(std::move(html), "<!-- viewer.css -->", "<style>\n" + css + "\n</style>");
  return replace_line(std::move(html), "<!-- viewer.js -->", "<script>\n" + js + "\n</script>");
}

}  // namespace tfm
