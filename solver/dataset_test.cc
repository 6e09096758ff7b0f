// SPDX-License-Identifier: MIT
#include "solver/dataset.h"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "solver/face_measurement.h"
#include "solver/image_io.h"
#include "solver/light.h"
#include "solver/simulate.h"
#include "solver/status.h"
#include "solver/synthetic.h"

namespace translume {
namespace {

namespace fs = std::filesystem;

class DatasetFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("translume_dataset_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    d_.shape = {8, 6, 4};
    d_.spacing_mm = 0.5;
    d_.C = 2.6;
    d_.setup = Setup::kFront;
    for (int l = 0; l < 2; ++l) {
      DatasetCondition c;
      c.name = "c" + std::to_string(l);
      c.q = GreyPattern(RasterizeLight(LightSpec::Parse(l ? "region:1,1/2" : "region:0,0/2"), d_.shape, 0.5));
      for (int ch = 0; ch < 3; ++ch) c.L[ch].assign(48, 0.1f * (ch + 1));
      c.mask = MeasurementMask(d_.shape, d_.setup, c.q, 1);
      d_.conditions.push_back(c);
    }
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Json() const { return (dir_ / "dataset.json").string(); }
  void Rewrite(const std::string& from, const std::string& to) {
    std::ifstream in(Json());
    std::string s((std::istreambuf_iterator<char>(in)), {});
    const size_t at = s.find(from);
    ASSERT_NE(at, std::string::npos) << from;
    s.replace(at, from.size(), to);
    std::ofstream(Json()) << s;
  }
  // Reading fails with one line that contains every piece of `what`.
  void ExpectError(const std::vector<std::string>& what) {
    try {
      ReadDataset(dir_.string());
      ADD_FAILURE() << "no error";
    } catch (const InputError& e) {
      const std::string msg = e.what();
      EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
      for (const auto& w : what) EXPECT_NE(msg.find(w), std::string::npos) << msg << " lacks " << w;
    }
  }
  fs::path dir_;
  Dataset d_;
};

TEST_F(DatasetFiles, RoundTripsExactly) {
  WriteDataset(dir_.string(), d_);
  const Dataset r = ReadDataset(Json());
  EXPECT_EQ(r.shape, d_.shape);
  EXPECT_EQ(r.setup, Setup::kFront);
  EXPECT_DOUBLE_EQ(r.C, 2.6);
  ASSERT_EQ(r.conditions.size(), 2u);
  for (size_t l = 0; l < 2; ++l) {
    EXPECT_EQ(r.conditions[l].name, d_.conditions[l].name);
    EXPECT_EQ(r.conditions[l].q, d_.conditions[l].q);
    EXPECT_EQ(r.conditions[l].L, d_.conditions[l].L);
    EXPECT_EQ(r.conditions[l].mask, d_.conditions[l].mask);
  }
  EXPECT_TRUE(fs::exists(dir_ / "mask_c0.exr"));
}

TEST_F(DatasetFiles, RejectsBrokenFilesWithOneLineNamingFileAndField) {
  ExpectError({"dataset.json", "no such file"});
  WriteDataset(dir_.string(), d_);
  Rewrite("translume-dataset/1", "translume-dataset/9");
  ExpectError({"dataset.json", "format"});
  WriteDataset(dir_.string(), d_);
  Rewrite("\"setup\": \"front\"", "\"setup\": \"side\"");
  ExpectError({"dataset.json", "setup", "side"});
  WriteDataset(dir_.string(), d_);
  Rewrite("\"spacing_mm\": 0.5", "\"spacing_mm\": -1");
  ExpectError({"spacing_mm"});
  // Spacings far outside a sample's made the solver's matrices singular (a CHECK abort).
  WriteDataset(dir_.string(), d_);
  Rewrite("\"spacing_mm\": 0.5", "\"spacing_mm\": 1e-50");
  ExpectError({"dataset.json", "spacing_mm", "0.001..1000 mm", "1e-50"});
  WriteDataset(dir_.string(), d_);
  Rewrite("\"C\": 2.6", "\"C\": 1e300");
  ExpectError({"dataset.json", "\"C\"", "1..1000"});
  // Data without any light, and a channel without measured light, are named with the file (a
  // single dark condition is allowed: it adds nothing, but harms nothing).
  Dataset dark = d_;
  for (auto& plane : dark.conditions[1].q) std::fill(plane.begin(), plane.end(), 0.f);
  EXPECT_EQ(dark.Validate(), "");
  WriteDataset(dir_.string(), d_);
  for (const char* f : {"q_c0.exr", "q_c1.exr"})
    WriteImage((dir_ / f).string(), Image{8, 6, 3, std::vector<float>(144, 0.f)});
  ExpectError({"dataset.json", "no condition has light"});
  WriteDataset(dir_.string(), d_);
  std::vector<float> no_green(144, 0.1f);
  for (size_t p = 1; p < no_green.size(); p += 3) no_green[p] = 0;
  for (const char* f : {"L_c0.exr", "L_c1.exr"}) WriteImage((dir_ / f).string(), Image{8, 6, 3, no_green});
  ExpectError({"dataset.json", "channel G has no light"});
  WriteDataset(dir_.string(), d_);
  Rewrite("\"C\": 2.6", "\"C\": \"x\"");
  ExpectError({"\"C\"", "wrong type"});
  WriteDataset(dir_.string(), d_);
  Rewrite("\"L\": \"L_c1.exr\"", "\"L\": \"L_nope.exr\"");
  ExpectError({"L_nope.exr", "no such file"});
  WriteDataset(dir_.string(), d_);
  Rewrite("\"name\": \"c1\"", "\"name\": \"c0\"");
  ExpectError({"conditions[1]", "c0", "twice"});
  WriteDataset(dir_.string(), d_);
  Rewrite("\"q\": \"q_c1.exr\"", "\"q\": \"mask_c1.exr\"");
  ExpectError({"mask_c1.exr", "q", "channels"});
  WriteDataset(dir_.string(), d_);
  WriteImage((dir_ / "L_c0.exr").string(), Image{5, 6, 3, std::vector<float>(90, 0.f)});
  ExpectError({"L_c0.exr", "5x6", "8x6"});
  WriteDataset(dir_.string(), d_);
  WriteImage((dir_ / "mask_c0.exr").string(), Image{8, 6, 1, std::vector<float>(48, 2.f)});
  ExpectError({"mask_c0.exr", "[0, 1]"});
  WriteDataset(dir_.string(), d_);
  std::vector<float> bad(144, 0.1f);
  bad[7] = NAN;
  WriteImage((dir_ / "L_c1.exr").string(), Image{8, 6, 3, bad});
  ExpectError({"L_c1.exr", "non-finite"});
  // Radiance as 8-bit PNG would be rounded to 1/255 of white; a light pattern as PNG is exact.
  WriteDataset(dir_.string(), d_);
  WriteImage((dir_ / "L_c1.png").string(), Image{8, 6, 3, std::vector<float>(144, 0.1f)});
  Rewrite("\"L\": \"L_c1.exr\"", "\"L\": \"L_c1.png\"");
  ExpectError({"L_c1.png", "8-bit", "float"});
  WriteDataset(dir_.string(), d_);
  const FacePattern& q = d_.conditions[1].q;
  WriteImage((dir_ / "q_c1.png").string(), ImageFromPlanes(8, 6, {q[0].data(), q[1].data(), q[2].data()}));
  Rewrite("\"q\": \"q_c1.exr\"", "\"q\": \"q_c1.png\"");
  EXPECT_EQ(ReadDataset(dir_.string()).conditions[1].q, d_.conditions[1].q);
  WriteDataset(dir_.string(), d_);
  Rewrite("\"grid\": [", "\"grid\": [1,");
  ExpectError({"grid"});
  // Condition names become parts of file names (q_NAME.exr): nothing that leaves the folder.
  for (const char* bad : {"../x", "a/b", "..", ""}) {
    WriteDataset(dir_.string(), d_);
    Rewrite("\"name\": \"c1\"", fmt::format("\"name\": \"{}\"", bad));
    ExpectError({"conditions[1]", "name", "[A-Za-z0-9_.-]"});
  }
  std::ofstream(Json()) << "{ not json";
  ExpectError({"dataset.json", "not valid JSON", "line 1, column 4"});
  // A number beyond a double's range: the parser's reason, with the number.
  WriteDataset(dir_.string(), d_);
  Rewrite("\"C\": 2.6", "\"C\": 1e999");
  ExpectError({"dataset.json: not valid JSON: number overflow parsing '1e999'"});
}

TEST(Dataset, SafeConditionNames) {
  for (const char* good : {"c0", "region_1.2-3", "A"}) EXPECT_TRUE(IsSafeConditionName(good)) << good;
  for (const char* bad : {"", ".", "..", "../x", "a/b", "a\\b", "sp ace", "x\n"})
    EXPECT_FALSE(IsSafeConditionName(bad)) << bad;
  EXPECT_TRUE(IsSafeConditionName(std::string(100, 'a')));
  EXPECT_FALSE(IsSafeConditionName(std::string(101, 'a')));
}

TEST(Simulate, RefineKeepsCoarseNodesAndInterpolates) {
  Material m = Material::Constant({3, 3, 2}, 1.0, {1, 1, 1}, {1, 1, 1});
  m.kappa[0][m.shape.index(1, 1, 1)] = 3;
  const Material f = RefineMaterial(m, 2);
  EXPECT_EQ(f.shape, (GridShape{5, 5, 3}));
  EXPECT_DOUBLE_EQ(f.spacing_mm, 0.5);
  EXPECT_FLOAT_EQ(f.kappa[0][f.shape.index(2, 2, 2)], 3);
  EXPECT_FLOAT_EQ(f.kappa[0][f.shape.index(2, 2, 1)], 2);
  EXPECT_FLOAT_EQ(f.kappa[0][f.shape.index(1, 2, 1)], 1.5);
  EXPECT_FLOAT_EQ(f.kappa[0][f.shape.index(4, 4, 0)], 1);
}

// No inverse crime (SPEC section 5): the data come from the 2x finer grid, the camera's box
// means (BoxMeansOfFineFace) of the refined material's own solve, and differ from a solve on
// the recovery grid by its discretisation error (~2 % on this 5-node-thick marble: far more
// than the solves' 1e-9).
TEST(Simulate, OversampledDataComeFromTheFinerGrid) {
  const SynthOptions syn{.preset = "marble", .shape = {10, 8, 5}};
  const Material m = SynthesizeMaterial(syn);
  SimulateOptions o;
  o.lights = {LightSpec::Parse("uniform")};
  const Dataset fine_data = SimulateDataset(m, o).training;
  o.oversample = 1;
  const Dataset coarse_data = SimulateDataset(m, o).training;
  MultigridOptions mg;
  mg.tolerance = 1e-11;
  const Material fine = RefineMaterial(m, 2);
  const FacePattern uniform = GreyPattern(std::vector<float>(fine.shape.face_size(), 1.0f));
  const FacePattern fine_L = RenderFrontFace(fine, Setup::kBack, {uniform}, mg)[0];
  // The recovery grid's own radiance at its nodes, for the border check below.
  const FacePattern nodes = RenderFrontFace(m, Setup::kBack, {GreyPattern(std::vector<float>(m.shape.face_size(), 1.0f))}, mg)[0];
  double worst_fine = 0, num = 0, den = 0, border_measured = 0, border_nodes = 0;
  for (int c = 0; c < 3; ++c) {
    const std::vector<float> expected = BoxMeansOfFineFace(m.shape, 2, fine_L[c]);
    for (int64_t f = 0; f < m.shape.face_size(); ++f) {
      const double got = fine_data.conditions[0].L[c][f], want = expected[f];
      worst_fine = std::max(worst_fine, std::abs(got - want) / want);
      const double coarse = coarse_data.conditions[0].L[c][f];
      num += (got - coarse) * (got - coarse);
      den += got * got;
      const int64_t i = f % m.shape.nx, j = f / m.shape.nx;
      if (i == 0 || j == 0 || i == m.shape.nx - 1 || j == m.shape.ny - 1) {
        border_measured += (got - coarse) * (got - coarse);
        border_nodes += (got - nodes[c][f]) * (got - nodes[c][f]);
      }
    }
  }
  // At the face's border the camera sees the half box's mean, which the node's own value misses
  // by h L' / 4: the coarse grid's MeasureFace is nearer the finer grid's box means than its node
  // values are (RMS over the border nodes 0.15x theirs).
  EXPECT_LT(std::sqrt(border_measured), 0.3 * std::sqrt(border_nodes));
  EXPECT_LT(worst_fine, 1e-6);
  EXPECT_GT(std::sqrt(num / den), 3e-3);  // measured 1.7e-2 (and 1.1e-7 above)
}

TEST(Simulate, FrontMaskNoiseAndHoldout) {
  const Material m = Material::Constant({16, 12, 4}, 0.5, {0.2f, 0.2f, 0.2f}, {0.02f, 0.02f, 0.02f});
  SimulateOptions o;
  o.lights = RegionLights("2x2");
  o.setup = Setup::kFront;
  o.holdout = 3;
  const SimulatedData clean = SimulateDataset(m, o);
  ASSERT_EQ(clean.training.conditions.size(), 4u);
  ASSERT_EQ(clean.holdout.conditions.size(), 3u);
  EXPECT_EQ(clean.holdout_lights[0].kind, LightSpec::Kind::kSpot);
  // region:0,0/2 covers x < 3.75 mm, y < 2.75 mm: the dual boxes of nodes i <= 7, j <= 5.
  // Masked with a margin of 2 nodes, measured beyond.
  const auto& mask = clean.training.conditions[0].mask;
  EXPECT_EQ(mask[0], 0.0f);
  EXPECT_EQ(mask[9 + 16 * 2], 0.0f);
  EXPECT_EQ(mask[10 + 16 * 2], 1.0f);
  EXPECT_EQ(mask[2 + 16 * 7], 0.0f);
  EXPECT_EQ(mask[2 + 16 * 8], 1.0f);
  o.noise = 0.05;
  const SimulatedData noisy = SimulateDataset(m, o);
  double s1 = 0, s2 = 0;
  int count = 0;
  for (size_t l = 0; l < 4; ++l)
    for (int c = 0; c < 3; ++c)
      for (size_t p = 0; p < 192; ++p) {
        const double r = noisy.training.conditions[l].L[c][p] / clean.training.conditions[l].L[c][p] - 1;
        s1 += r;
        s2 += r * r;
        ++count;
      }
  EXPECT_NEAR(s1 / count, 0.0, 0.01);
  EXPECT_NEAR(std::sqrt(s2 / count), 0.05, 0.005);
  o.oversample = 0;
  EXPECT_THROW(SimulateDataset(m, o), InputError);
}

}  // namespace
}  // namespace translume
