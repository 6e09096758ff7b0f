// SPDX-License-Identifier: MIT
#include "calib/bench_exposure_times.h"

#include <gtest/gtest.h>

#include "calib/error.h"
#include "calib/test_util.h"

namespace translume::calib {
namespace {

// One scene per case: auto reads every bracket's labels as the camera exposed them, also with a
// black level left in linear photos, and its merge is as close to the truth as one with the true
// times; with a black stack the black level costs nothing. Without a black level the other reading is measurably worse (with one, the black level's
// own error in dark pixels swamps the difference).
TEST(ExposureTimesBench, AutoReadsEveryBracketAsTheCameraExposed) {
  ExposureTimesBenchOptions o;
  o.seeds = 1;
  o.size = {160, 120};
  const std::vector<ExposureTimesBenchRow> rows = RunExposureTimesBench(o);
  std::printf("%s\n", ExposureTimesBenchTable(rows).c_str());
  ASSERT_EQ(rows.size(), 2u * 4u + 2u * 4u * 2u);  // 8-bit: no offset rows
  for (const ExposureTimesBenchRow& r : rows) {
    SCOPED_TRACE(::testing::Message() << r.bits << "-bit " << r.bracket << " " << r.camera << " offset " << r.offset);
    EXPECT_EQ(r.right, 1);
    EXPECT_EQ(r.decisive, 1);
    EXPECT_NEAR(r.error_auto, r.error_true, 0.02 * r.error_true);
    const double wrong = r.camera == "apex" ? r.error_labelled : r.error_apex;
    if (r.offset == 0) {
      EXPECT_GT(wrong, 1.3 * r.error_auto);
    }
    EXPECT_GT(r.seconds_auto, 0);
    // A black stack removes the black level exposure by exposure: as good as none left in.
    if (r.bits == 16) {
      EXPECT_EQ(r.right_black, 1);
      if (r.offset == 0) {
        EXPECT_NEAR(r.error_black, r.error_true, 0.05 * r.error_true);
      } else {
        EXPECT_LT(r.error_black, 0.6 * r.error_auto);
      }
    } else {
      EXPECT_EQ(r.error_black, -1);
    }
  }
  EXPECT_NE(ExposureTimesBenchJson(rows).find("\"error_true\""), std::string::npos);
}

TEST(ExposureTimesBench, Brackets) {
  EXPECT_EQ(ExposureTimesBracket("1/60:1/30:0.3"), (std::vector<double>{1 / 60., 1 / 30., 0.3}));
  EXPECT_EQ(ExposureTimesBracket("full").size(), 9u);
  EXPECT_EQ(CalibErrorOf([] { ExposureTimesBracket("slow"); }),
            "bracket 'slow': not one of full, fast, thirds, halves nor times joined by ':' (1/60:1/30:1/15)");
  EXPECT_EQ(CalibErrorOf([] { ExposureTimesBracket("1/60:1/x"); }),
            "bracket '1/60:1/x': '1/x' is no exposure time (seconds or 1/N)");
  EXPECT_EQ(CalibErrorOf([] { ExposureTimesBracket("1/60:1/60"); }),
            "bracket '1/60:1/60': needs two or more different times");
  ExposureTimesBenchOptions o;
  o.bits = {12};
  EXPECT_EQ(o.Validate(), "--bits: 12 is neither 8 nor 16");
  o = {};
  o.cameras = {"canon"};
  EXPECT_EQ(o.Validate(), "--cameras: 'canon' is neither apex nor exact");
  o = {};
  o.brackets = {"full", "1/8:1/8"};
  EXPECT_EQ(o.Validate(), "--brackets: bracket '1/8:1/8': needs two or more different times");
}

}  // namespace
}  // namespace translume::calib
