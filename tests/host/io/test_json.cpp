// host/io/json.h: every file reads nlohmann::json through it, so a read that has no answer — a
// missing key of a const object — throws std::logic_error instead of being undefined behaviour
// in NDEBUG builds (the default RelWithDebInfo), where nlohmann's own assert() is off.
#include <stdexcept>
#include <string>

#include <gtest/gtest.h>

#include "tfmatch/io/json.h"

namespace tfm {
namespace {

TEST(Json, AMissingKeyOfAConstObjectThrowsInEveryBuild) {
  const nlohmann::json doc = nlohmann::json::parse(R"({"present": 1})");
  EXPECT_EQ(doc["present"].get<int>(), 1);
  try {
    const nlohmann::json& missing = doc["absent"];
    ADD_FAILURE() << "no exception; read " << missing.dump();
  } catch (const std::logic_error& e) {
    EXPECT_NE(std::string(e.what()).find("nlohmann::json"), std::string::npos) << e.what();
  }
  // What the library reports as its own errors stays its own exception type.
  EXPECT_THROW((void)doc.at("absent"), nlohmann::json::out_of_range);
}

}  // namespace
}  // namespace tfm
