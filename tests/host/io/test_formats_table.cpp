// The table of volume formats (host/io/volume_format_table.h): every row is detected by each of its
// extensions and, where it has one, by its first bytes; the unknown-format message, `tfmatch info`
// and its help list every row; selections a format does not have are refused by name.
#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <map>
#include <set>

#include "cli_runner.h"
#include "formats_test_util.h"
#include "tfmatch/io/volume_format_table.h"
#include "tfmatch/io/volume_info.h"
#include "tfmatch/io/volume_io.h"

namespace tfm {
namespace {

using formats_test::expect_error;
using formats_test::TempDir;

// The first bytes of a file of each format that has a sniffer (several variants where the format
// has several signatures). A new row with a sniffer needs its sample here.
const std::map<std::string, std::vector<std::string>>& magic_samples() {
  static const std::map<std::string, std::vector<std::string>> samples = {
      {"netcdf", {std::string("CDF\x01\0\0\0\0", 8), std::string("CDF\x02\0\0\0\0", 8), std::string("CDF\x05\0\0\0\0", 8),
                  std::string("\x89HDF\r\n\x1a\n\0\0", 10)}},
      {"grib", {"GRIB\x00\x00\x00\x02"}},
      {"vtk", {"# vtk DataFile Version 3.0\ntitle\nASCII\n", "# VTK DATAFILE Version 2.0\n"}},
      {"vti", {"<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\">\n", "<VTKFile type=\"ImageData\" version=\"1.0\">"}},
      {"nrrd", {"NRRD0004\ntype: uchar\n", "NRRD0001\n"}},
  };
  return samples;
}

std::string upper(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::toupper(c); });
  return s;
}

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

TEST(FormatsTable, RowsAreCompleteAndDistinct) {
  std::set<std::string> names, extensions;
  ASSERT_FALSE(volume_formats().empty());
  for (const VolumeFormat& f : volume_formats()) {
    SCOPED_TRACE(f.name);
    EXPECT_TRUE(names.insert(f.name).second) << "duplicate name";
    EXPECT_FALSE(f.title.empty());
    EXPECT_FALSE(f.description.empty());
    EXPECT_TRUE(f.read != nullptr);
    EXPECT_TRUE(f.describe != nullptr);
    ASSERT_FALSE(f.extensions.empty());
    for (const std::string& e : f.extensions) {
      EXPECT_TRUE(e.size() > 1 && e[0] == '.') << e;
      EXPECT_EQ(e, lower(e));
      EXPECT_TRUE(extensions.insert(e).second) << "extension " << e << " in two rows";
    }
  }
}

TEST(FormatsTable, DetectsEveryRowByEachExtension) {
  TempDir dir;
  for (const VolumeFormat& f : volume_formats()) {
    for (const std::string& e : f.extensions) {
      // The extension decides, whatever the bytes say (here another format's magic).
      const auto p = dir / ("file" + e);
      formats_test::write_bytes(p, f.name == "grib" ? "NRRD0004\n" : "GRIB");
      EXPECT_EQ(detect_volume_format(p), f.name) << e;
      ASSERT_NE(find_volume_format(p), nullptr);
      EXPECT_EQ(find_volume_format(p)->name, f.name);
      const auto q = dir / ("FILE" + upper(e));
      formats_test::write_bytes(q, "x");
      EXPECT_EQ(detect_volume_format(q), f.name) << "case-insensitive: " << upper(e);
    }
  }
}

TEST(FormatsTable, DetectsEveryRowWithASnifferByItsFirstBytes) {
  TempDir dir;
  int sniffed = 0;
  for (const VolumeFormat& f : volume_formats()) {
    if (!f.sniff) continue;
    ++sniffed;
    auto it = magic_samples().find(f.name);
    ASSERT_NE(it, magic_samples().end()) << f.name << " has a sniffer: add a sample of its first bytes here";
    for (const std::string& head : it->second) {
      const auto p = dir / (f.name + ".unknown-extension");
      formats_test::write_bytes(p, head);
      EXPECT_EQ(detect_volume_format(p), f.name) << "sample: " << head;
      // Exactly this row's sniffer accepts it (so table order does not decide).
      for (const VolumeFormat& g : volume_formats())
        if (g.sniff && &g != &f) EXPECT_FALSE(g.sniff(head)) << g.name << " also accepts " << f.name << "'s bytes";
    }
  }
  EXPECT_GE(sniffed, 5);
  // Formats without a signature (raw, .dat) are known by extension only; bytes nobody claims are unknown.
  const auto p = dir / "mystery.bin";
  formats_test::write_bytes(p, "ObjectFileName: x.raw\nResolution: 1 1 1\nFormat: UCHAR\n");
  EXPECT_EQ(detect_volume_format(p), "");
  EXPECT_EQ(find_volume_format(p), nullptr);
  formats_test::write_bytes(p, "");
  EXPECT_EQ(detect_volume_format(p), "");
}

TEST(FormatsTable, UnknownFormatMessageListsEveryRow) {
  TempDir dir;
  const auto p = dir / "mystery.xyz";
  formats_test::write_bytes(p, "hello");
  for (const VolumeFormat& f : volume_formats()) {
    std::initializer_list<std::string> parts = {"mystery.xyz", "unknown volume format '.xyz'", f.title};
    expect_error([&] { load_volume(p.string()); }, parts);
    expect_error([&] { describe_file(p); }, parts);  // `tfmatch info` says the same
    for (const std::string& e : f.extensions) {
      expect_error([&] { load_volume(p.string()); }, {e});
    }
  }
}

TEST(FormatsTable, SelectionsAFormatDoesNotHaveAreRefused) {
  TempDir dir;
  const std::string times = volume_format_titles(&VolumeFormat::has_times);
  const std::string members = volume_format_titles(&VolumeFormat::has_members);
  EXPECT_EQ(times, "NetCDF and GRIB");
  for (const VolumeFormat& f : volume_formats()) {
    SCOPED_TRACE(f.name);
    // The checks come before the reader, so the bytes do not matter.
    const std::string file = (dir / ("f" + f.extensions.front())).string();
    formats_test::write_bytes(file, "not really " + f.name);
    if (!f.has_times)
      expect_error([&] { load_volume(file + ":,time=1"); }, {file, "time selection", times + " files only"});
    if (!f.has_members)
      expect_error([&] { load_volume(file + ":,member=2"); }, {file, "member selection", members + " files only"});
    if (!f.has_variables() && !f.has_components)
      expect_error([&] { load_volume(file + ":x"); }, {file, "holds one array", "remove ':x'"});
  }
  // A time or member index of 0 (what --time/--member default to) is not refused: it reaches the reader.
  std::string vtk = "# vtk DataFile Version 3.0\nt\nASCII\nDATASET STRUCTURED_POINTS\nDIMENSIONS 2 1 1\nPOINT_DATA 2\n"
                    "SCALARS s float\nLOOKUP_TABLE default\n1 2\n";
  formats_test::write_bytes(dir / "ok.vtk", vtk);
  EXPECT_EQ(load_volume((dir / "ok.vtk").string() + ":s,time=0,member=0").values, (std::vector<float>{1, 2}));
  expect_error([&] { load_volume((dir / "ok.vtk").string() + ":s,time=3"); },
               {"ok.vtk", "time selection", "NetCDF and GRIB files only", "a VTK file has no time axis"});
}

TEST(FormatsTable, ListsForMessagesAndHelp) {
  EXPECT_EQ(volume_format_titles(nullptr, " or "), "NetCDF, GRIB, VTK, VTI, NRRD, raw or .dat");
  const std::string selectors = volume_format_selectors();
  const std::string supported = supported_volume_formats();
  const std::string help = volume_format_help();
  for (const VolumeFormat& f : volume_formats()) {
    if (f.has_variables()) EXPECT_NE(selectors.find(f.title + " " + f.selects), std::string::npos) << selectors;
    for (const std::string& e : f.extensions) {
      EXPECT_NE(supported.find(e), std::string::npos) << supported;
      EXPECT_NE(help.find(e), std::string::npos) << help;
    }
    EXPECT_NE(help.find(f.description), std::string::npos) << help;
  }
}

TEST(FormatsTableCli, InfoHelpListsEveryFormat) {
  test::CliResult r = test::run_cli("info --help");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const VolumeFormat& f : volume_formats()) {
    EXPECT_NE(r.output.find(f.description), std::string::npos) << f.name << "\n" << r.output;
    for (const std::string& e : f.extensions) EXPECT_NE(r.output.find(e), std::string::npos) << e << "\n" << r.output;
  }
  // Unknown files: non-zero exit, and the list of formats.
  TempDir dir;
  formats_test::write_bytes(dir / "mystery.xyz", "hello");
  r = test::run_cli("info " + (dir / "mystery.xyz").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("unknown volume format '.xyz'"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(".nhdr"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace tfm
