// Words as a POSIX shell needs them typed, for the commands tfmatch records (a report's
// command.txt) so that they can be pasted back into a shell.
#pragma once

#include <string>

namespace tfm {

// `word` as it is where it has only [A-Za-z0-9_./:=,+-@%], else in single quotes with each '
// written as '\'' ("it's" -> 'it'\''s'; the empty word -> '').
std::string shell_word(const std::string& word);

}  // namespace tfm
