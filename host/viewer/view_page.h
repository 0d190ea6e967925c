// The page of `tfmatch view` (host/viewer/page/): index.html with viewer.css and viewer.js
// inlined, from the copies built into the binary or, for editing, from a directory.
#pragma once

#include <string>

namespace tfm {

// Replaces the line "<!-- viewer.css -->" of index.html by a <style> element holding viewer.css
// and "<!-- viewer.js -->" by a <script> element holding viewer.js. `assets_dir` empty: the
// built-in files; else that directory's (throws std::runtime_error naming a missing file).
std::string view_page_html(const std::string& assets_dir = "");

}  // namespace tfm
