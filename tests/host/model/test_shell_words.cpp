// Recorded commands paste back into a shell: words quoted only where a shell would split or
// expand them, a single quote inside one written as '\''.
#include <gtest/gtest.h>

#include <cstdio>
#include <string>

#include "tfmatch/model/shell_words.h"

namespace tfm {
namespace {

TEST(ShellWords, QuotedOnlyWhereAShellWouldChangeThem) {
  EXPECT_EQ(shell_word("/tmp/run-1/ref_8x8x8_float32.raw"), "/tmp/run-1/ref_8x8x8_float32.raw");
  EXPECT_EQ(shell_word("uvt.nc:U,time=0"), "uvt.nc:U,time=0");
  EXPECT_EQ(shell_word("my data/a b.nc"), "'my data/a b.nc'");
  EXPECT_EQ(shell_word("dir/*.vti"), "'dir/*.vti'");
  EXPECT_EQ(shell_word("$HOME"), "'$HOME'");
  EXPECT_EQ(shell_word("it's"), "'it'\\''s'");
  EXPECT_EQ(shell_word(""), "''");
  // What the shell makes of a quoted word is the word itself.
  for (const std::string word : {"it's a 'test'", "a b\tc", "$(rm -rf x)", "\"q\""}) {
    FILE* shell = ::popen(("printf %s " + shell_word(word)).c_str(), "r");
    ASSERT_NE(shell, nullptr);
    std::string back;
    char buf[256];
    while (size_t n = std::fread(buf, 1, sizeof buf, shell)) back.append(buf, n);
    ::pclose(shell);
    EXPECT_EQ(back, word);
  }
}

}  // namespace
}  // namespace tfm
