// The memory budget (host/model/memory_budget.h) and the cancellation flag
// (host/model/cancellation.h): sizes as users write them, the check before an allocation and its
// message, what the machine reports, and Cancelled passing every std::exception handler.
#include <gtest/gtest.h>

#include <string>

#include "tfmatch/model/cancellation.h"
#include "tfmatch/model/memory_budget.h"

namespace tfm {
namespace {

TEST(MemoryBudget, ParsesSizesAsUsersWriteThem) {
  EXPECT_EQ(parse_byte_size("1000000"), 1000000u);
  EXPECT_EQ(parse_byte_size("64k"), 64u << 10);
  EXPECT_EQ(parse_byte_size("512M"), 512u << 20);
  EXPECT_EQ(parse_byte_size("512MB"), 512u << 20);
  EXPECT_EQ(parse_byte_size("2G"), uint64_t(2) << 30);
  EXPECT_EQ(parse_byte_size("1.5GiB"), uint64_t(3) << 29);
  EXPECT_EQ(parse_byte_size("1t"), uint64_t(1) << 40);
  EXPECT_EQ(parse_byte_size(".5G"), uint64_t(1) << 29);
  for (const char* bad : {"", "G", "-1G", "0", "0.1", "12X", "1e30G", "inf", "nan", " 1G", "0x10G", "1e3M", ".", "1.2.3G"})
    EXPECT_FALSE(parse_byte_size(bad)) << bad;
}

TEST(MemoryBudget, FormatsBytes) {
  EXPECT_EQ(format_bytes(512), "512 bytes");
  EXPECT_EQ(format_bytes(1536), "1.50 KiB");
  EXPECT_EQ(format_bytes(uint64_t(4) << 30), "4.00 GiB");
  EXPECT_EQ(format_bytes(uint64_t(120) << 30), "120 GiB");
}

TEST(MemoryBudget, RefusesBeforeAllocatingAndSaysWhy) {
  // The process holds its resident memory already: a budget of that plus 64 MiB leaves 64 MiB.
  const uint64_t in_use = resident_memory();
  ASSERT_GT(in_use, 0u);
  set_memory_budget(in_use + (uint64_t(64) << 20), "--max-memory test");
  EXPECT_NO_THROW(check_memory(uint64_t(1) << 20, "small"));
  try {
    check_memory(uint64_t(4) << 30, "big.nrrd: 1024x1024x1024 volume");
    ADD_FAILURE() << "4 GiB passed a budget of 64 MiB";
  } catch (const MemoryBudgetExceeded& e) {
    const std::string m = e.what();
    for (const char* needle : {"big.nrrd: 1024x1024x1024 volume", "needs 4.00 GiB", "--max-memory test", "in use"})
      EXPECT_NE(m.find(needle), std::string::npos) << m;
  }
  EXPECT_THROW(check_memory(UINT64_MAX, "overflow"), MemoryBudgetExceeded);
  set_memory_budget(0, "");  // back to the default: what the machine has
  const MemoryBudget budget = memory_budget();
  EXPECT_GT(budget.bytes, in_use);
  EXPECT_NE(budget.source.find("available"), std::string::npos) << budget.source;
  EXPECT_GT(available_memory(), 0u);
}

// Memory that work on another thread is about to take counts as in use until released.
TEST(MemoryBudget, ReservationsCountUntilReleased) {
  set_memory_budget(resident_memory() + (uint64_t(64) << 20), "--max-memory test");
  const uint64_t need = uint64_t(16) << 20;
  EXPECT_NO_THROW(check_memory(need, "a field"));
  {
    MemoryReservation device(uint64_t(56) << 20, "the device starting");
    try {
      check_memory(need, "a field");
      ADD_FAILURE() << "16 MiB passed with 8 MiB left beside a reservation";
    } catch (const MemoryBudgetExceeded& e) {
      EXPECT_NE(std::string(e.what()).find("56.0 MiB of them set aside for the device starting"), std::string::npos)
          << e.what();
    }
    device.release();
    EXPECT_NO_THROW(check_memory(need, "a field"));
    device.release();  // once only
    EXPECT_NO_THROW(check_memory(need, "a field"));
  }
  {
    const MemoryReservation held(uint64_t(56) << 20, "the device starting");
    EXPECT_THROW(check_memory(need, "a field"), MemoryBudgetExceeded);
  }
  EXPECT_NO_THROW(check_memory(need, "a field"));  // released by its destructor
  set_memory_budget(0, "");
}

TEST(Cancellation, PassesStdExceptionHandlersAndResets) {
  EXPECT_FALSE(cancel_requested());
  EXPECT_NO_THROW(check_cancelled());
  request_cancel(15);
  request_cancel(2);  // the first request's signal is kept
  EXPECT_TRUE(cancel_requested());
  // Requested but not yet seen by the work: the watchdog must not wait for a teardown.
  EXPECT_FALSE(cancel_acknowledged());
  int signal = -1;
  try {
    try {
      checkpoint("solve");
    } catch (const std::exception&) {
      ADD_FAILURE() << "caught as a std::exception";
    }
  } catch (const Cancelled& c) {
    signal = c.signal();
  }
  EXPECT_EQ(signal, 15);
  EXPECT_TRUE(cancel_acknowledged());  // a check threw: the work is unwinding
  reset_cancel();
  EXPECT_FALSE(cancel_acknowledged());
  EXPECT_NO_THROW(checkpoint("solve"));
}

}  // namespace
}  // namespace tfm
