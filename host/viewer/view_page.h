// The page of `tfmatch view` (host/viewer/page/): index.html with viewer.css and the script's
// parts inlined, from the copies built into the binary or, for editing, from a directory.
#pragma once

#include <string>
#include <vector>

namespace tfm {

// Replaces the line "<!-- viewer.css -->" of index.html by a <style> element holding viewer.css
// and "<!-- viewer script -->" by a <script> element holding the script's parts, in the order of
// view_page_script_parts(), inside one function scope. `assets_dir` empty: the built-in files;
// else that directory's (throws std::runtime_error naming a missing file).
std::string view_page_html(const std::string& assets_dir = "");

// The file names of the script's parts (host/viewer/page/viewer_*.js), in the order they run.
std::vector<std::string> view_page_script_parts();

}  // namespace tfm
