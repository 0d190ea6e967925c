// The CUDA solvers' plugin as a user meets it (a build with TFMATCH_CUDA): commands that run no
// CUDA solver never load CUDA's libraries (the dynamic loader's own log says which it loads), a
// CUDA solver loads the plugin beside the program by itself, and a plugin that cannot be loaded is
// a clear error naming it, with nothing written.
#ifdef TFMATCH_HAVE_CUDA

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "cli_runner.h"
#include "tfmatch/io/json.h"

namespace tfm {
namespace {

using test::run_cli;

using test::loader_log_shows;

class CudaPluginCli : public ::testing::Test {
 protected:
  void SetUp() override {
    std::vector<float> ref(64), field(64);
    for (size_t i = 0; i < 64; ++i) ref[i] = float(i % 17) / 16.0f, field[i] = 3.0f * ref[i];
    test::write_floats(dir / "ref_4x4x4_float32.raw", ref);
    test::write_floats(dir / "field_4x4x4_float32.raw", field);
    std::ofstream(dir / "tf.json") << R"({"rgba": [[0,0,0,0],[1,0.5,0.2,0.8],[0.2,0.4,1,1]]})";
  }
  std::string optimize(const std::string& solver) {
    return "optimize --ref " + dir / "ref_4x4x4_float32.raw" + " --field " + dir / "field_4x4x4_float32.raw" +
           " --ref-tf " + dir / "tf.json" + " --solver " + solver + " --out " + dir / "out.json";
  }
  test::TempDir dir;
};

TEST_F(CudaPluginCli, OnlyACudaSolverLoadsCuda) {
  // The test program names the build's plugin in TFMATCH_CUDA_PLUGIN; the program finds its own.
  const test::CliEnvironment env{{"LD_DEBUG", "libs"}, {"TFMATCH_CUDA_PLUGIN", ""}};
  for (const std::string args : {std::string("--version"), optimize("normal-equations")}) {
    const test::CliResult r = run_cli(args, test::kCliTimeout, env);
    ASSERT_EQ(r.exit_code, 0) << args << "\n" << r.output;
    ASSERT_TRUE(loader_log_shows(r.output, "libc.so.6")) << "no loader log: " << r.output.substr(0, 2000);
    for (const std::string library : {"libtfmatch_cuda.so", "libcudart.so", "libcusparse.so", "libnvJitLink.so"})
      EXPECT_FALSE(loader_log_shows(r.output, library)) << args << " loaded " << library;
  }
  std::filesystem::remove(dir / "out.json");

  const test::CliResult r = run_cli(optimize("cuda-cgls"), test::kCliTimeout, env);
  EXPECT_TRUE(loader_log_shows(r.output, "libtfmatch_cuda.so")) << r.output.substr(0, 4000);
  EXPECT_TRUE(loader_log_shows(r.output, "libcusparse.so")) << r.output.substr(0, 4000);
  if (r.exit_code != 0) {  // no CUDA device here: the solver says so, the plugin is not the problem
    EXPECT_EQ(r.exit_code, 1);
    EXPECT_NE(r.output.find("cuda-cgls: no CUDA device available"), std::string::npos) << r.output;
    EXPECT_FALSE(std::filesystem::exists(dir / "out.json"));
  }
}

// `devices` names the plugin and the CUDA device, or says why the CUDA solvers cannot run.
TEST_F(CudaPluginCli, DevicesSaysWhatTheCudaSolversSee) {
  const test::CliResult r = run_cli("devices --json - 2>/dev/null", test::kCliTimeout, {{"TFMATCH_CUDA_PLUGIN", ""}});
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json cuda = nlohmann::json::parse(r.output)["cuda"];
  EXPECT_EQ(cuda["built"], true);
  EXPECT_EQ(cuda["plugin"], std::string(TFMATCH_BUILD_DIR) + "/libtfmatch_cuda.so");  // beside the program
  if (cuda.contains("device"))
    EXPECT_FALSE(cuda["device"].get<std::string>().empty());
  else
    EXPECT_EQ(cuda["error"].get<std::string>().rfind("no CUDA device available (cudaGetDeviceCount: ", 0), 0u) << cuda;

  std::ofstream(dir / "libtfmatch_cuda.so") << "not a shared library";
  const test::CliResult text = run_cli("devices", test::kCliTimeout, {{"TFMATCH_CUDA_PLUGIN", dir / "libtfmatch_cuda.so"}});
  EXPECT_EQ(text.exit_code, 0) << text.output;  // the Vulkan devices are still there
  EXPECT_NE(text.output.find("CUDA solvers: cannot run: the CUDA solvers' plugin " + dir / "libtfmatch_cuda.so" +
                             " cannot be loaded: "),
            std::string::npos)
      << text.output;
}

TEST_F(CudaPluginCli, APluginThatCannotBeLoadedIsAClearError) {
  std::ofstream(dir / "libtfmatch_cuda.so") << "not a shared library";
  for (const std::string& plugin : {dir / "missing/libtfmatch_cuda.so", dir / "libtfmatch_cuda.so"}) {
    const test::CliResult r = run_cli(optimize("cuda-normal-equations"), test::kCliTimeout,
                                      {{"TFMATCH_CUDA_PLUGIN", plugin}});
    EXPECT_EQ(r.exit_code, 1) << r.output;
    EXPECT_NE(r.output.find("cuda-normal-equations: the CUDA solvers' plugin " + plugin + " cannot be loaded: "),
              std::string::npos)
        << r.output;
    EXPECT_FALSE(std::filesystem::exists(dir / "out.json"));
  }
}

}  // namespace
}  // namespace tfm

#endif  // TFMATCH_HAVE_CUDA
