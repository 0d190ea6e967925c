// The viewer page, assembled from index.html, viewer.css and the script's parts.
#include "tfmatch/viewer/view_page.h"

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

// The script's parts in the order they run: each may use what the ones before it declare.
struct ScriptPart {
  const char* name;
  std::string_view (*built_in)();
};
constexpr ScriptPart kScriptParts[] = {
    {"viewer_core.js", view_asset_viewer_core_js},   {"viewer_views.js", view_asset_viewer_views_js},
    {"viewer_panels.js", view_asset_viewer_panels_js}, {"viewer_jobs.js", view_asset_viewer_jobs_js},
    {"viewer_tf_editor.js", view_asset_viewer_tf_editor_js}, {"viewer_start.js", view_asset_viewer_start_js},
};

}  // namespace

std::vector<std::string> view_page_script_parts() {
  std::vector<std::string> names;
  for (const ScriptPart& p : kScriptParts) names.emplace_back(p.name);
  return names;
}

std::string view_page_html(const std::string& assets_dir) {
  const bool built_in = assets_dir.empty();
  std::string html = built_in ? std::string(view_asset_index_html()) : read_asset(assets_dir, "index.html");
  const std::string css = built_in ? std::string(view_asset_viewer_css()) : read_asset(assets_dir, "viewer.css");
  // One function scope around the parts: they share their names with each other, not with the
  // window (the page exposes only window.tfmViewer).
  std::string js = "(() => {\n'use strict';\n";
  for (const ScriptPart& p : kScriptParts) js += built_in ? std::string(p.built_in()) : read_asset(assets_dir, p.name);
  js += "})();";
  html = replace_line(std::move(html), "<!-- viewer.css -->", "<style>\n" + css + "\n</style>");
  return replace_line(std::move(html), "<!-- viewer script -->", "<script>\n" + js + "\n</script>");
}

}  // namespace tfm
