// `synthdrive synth` as a batch: shards write parts, the merge writes the dataset, and the result is the same
// bytes as a local run; a shard killed mid-part resumes; merges refuse missing parts and parts of another
// request; a failing frame does not stop the others. On the repo's 3-frame KITTI log, so a 2-shard split is
// uneven (frames 0, 2 | 1).
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>
#include <thread>

#include <gtest/gtest.h>

#include "assetgen/canonical.h"
#include "datasets/coco.h"
#include "io/files.h"
#include "io/geometry_json.h"
#include "io/json.h"
#include "io/mesh_io.h"
#include "synth/batch.h"
#include "synth/report.h"
#include "synth/test_assets.h"
#include "testing/input_error.h"
#include "testing/testing.h"

namespace sd {
namespace {

namespace fs = std::filesystem;

const char* kCrashChildEnv = "SD_SYNTH_CRASH_CHILD";

// The pipeline tests' assets, a scenario that fits on all three KITTI frames (the demo's car finds no room in
// frame 0), cheap render settings.
const char* kKittiScenario = R"({"seed": 7, "margin_m": 0.5, "objects": [
  {"category": "traffic_cone", "count": 2, "distance_m": [5, 20], "lateral_m": [-4, 4], "yaw": "random"},
  {"category": "barrier", "count": 1, "distance_m": [5, 25], "lateral_m": [-5, 5], "yaw": "aligned"},
  {"category": "car", "count": 1, "distance_m": [5, 30], "lateral_m": [-6, 6], "yaw": "aligned"}]})";

SynthRequest KittiRequest(const fs::path& dir, const fs::path& out) {
  SynthRequest r;
  r.log = testing::RepoData("driving/kitti-object");
  r.assets = {dir / "cone", dir / "barrier", dir / "car"};
  r.scenario = dir / "kitti.json";
  r.out = out;
  r.options.samples_per_pixel = 1;
  r.options.ao_samples = 2;
  return r;
}

std::map<std::string, std::string> ReadTree(const fs::path& root) {
  std::map<std::string, std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(root))
    if (e.is_regular_file()) files[fs::relative(e.path(), root).string()] = ReadFileToString(e.path());
  return files;
}

// Every file under both trees, byte for byte (synth.json has no wall-clock fields, so nothing is excluded).
void ExpectSameTree(const fs::path& a, const fs::path& b) {
  const auto fa = ReadTree(a), fb = ReadTree(b);
  std::vector<std::string> na, nb;
  for (const auto& [k, v] : fa) na.push_back(k);
  for (const auto& [k, v] : fb) nb.push_back(k);
  ASSERT_EQ(na, nb) << a << " vs " << b;
  size_t differ = 0;
  for (const auto& [k, v] : fa)
    if (v != fb.at(k)) {
      ++differ;
      ADD_FAILURE() << k << " differs between " << a << " and " << b;
    }
  EXPECT_EQ(differ, 0u);
  EXPECT_GE(fa.size(), 5u);  // images, sweeps, labels, synth.json, report...
}

std::vector<nlohmann::json> ReadRunLog(const fs::path& file) {
  std::vector<nlohmann::json> lines;
  std::istringstream in(ReadFileToString(file));
  for (std::string line; std::getline(in, line);) lines.push_back(nlohmann::json::parse(line));
  return lines;
}

size_t Lines(const std::string& text) {
  std::istringstream in(text);
  size_t n = 0;
  for (std::string line; std::getline(in, line);) n += !line.empty();
  return n;
}

using testing::InputErrorOf;

class SynthBatchTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir();
    testing::ImportDemoAssets(dir_->path());
    WriteFileAtomic(dir_->path() / "kitti.json", kKittiScenario);
    local_ = new SynthSummary(RunSynth(KittiRequest(dir_->path(), dir_->path() / "local")));
    // Shards 0/2 and 1/2, in the order a scheduler may happen to run them.
    const SynthRequest r = KittiRequest(dir_->path(), dir_->path() / "sharded");
    shard1_ = new SynthShardSummary(RunSynthShard(r, ShardSpec{1, 2}));
    shard0_ = new SynthShardSummary(RunSynthShard(r, ShardSpec{0, 2}));
  }
  static void TearDownTestSuite() {
    delete shard0_;
    delete shard1_;
    delete local_;
    delete dir_;
  }
  static fs::path Dir() { return dir_->path(); }
  static testing::TempDir* dir_;
  static SynthSummary* local_;
  static SynthShardSummary *shard0_, *shard1_;
};
testing::TempDir* SynthBatchTest::dir_ = nullptr;
SynthSummary* SynthBatchTest::local_ = nullptr;
SynthShardSummary* SynthBatchTest::shard0_ = nullptr;
SynthShardSummary* SynthBatchTest::shard1_ = nullptr;

TEST_F(SynthBatchTest, LocalRunWritesTheDatasetAndRemovesItsParts) {
  EXPECT_EQ(local_->frames, 3u);
  EXPECT_EQ(local_->objects, 12u);  // 4 objects per frame
  EXPECT_FALSE(fs::exists(SynthPartsDir(Dir() / "local")));
  for (const char* f : {"000000", "000001", "000002"}) {
    const std::string in = ReadFileToString(testing::RepoData(std::string("driving/kitti-object/training/label_2/") + f + ".txt"));
    const std::string out = ReadFileToString(Dir() / "local" / "label_2" / (std::string(f) + ".txt"));
    EXPECT_EQ(out.substr(0, in.size()), in) << f;  // real labels kept, 4 lines added
    EXPECT_EQ(Lines(out), Lines(in) + 4) << f;
  }
}

TEST_F(SynthBatchTest, TwoShardsAndAMergeWriteTheSameBytesAsALocalRun) {
  EXPECT_EQ(shard0_->owned, 2u);  // selection positions 0 and 2
  EXPECT_EQ(shard0_->done, 2u);
  EXPECT_EQ(shard1_->owned, 1u);
  EXPECT_EQ(shard1_->done, 1u);
  EXPECT_TRUE(shard0_->failed.empty());
  const fs::path parts = SynthPartsDir(Dir() / "sharded");
  for (const char* p : {"0-000000", "1-000001", "2-000002"}) EXPECT_TRUE(fs::exists(parts / p / "part.json")) << p;
  const auto log0 = ReadRunLog(parts / "log-0-of-2.jsonl");
  ASSERT_EQ(log0.size(), 2u);
  EXPECT_EQ(log0[0]["frame"], 0);
  EXPECT_EQ(log0[1]["frame"], 2);
  for (const auto& l : log0) EXPECT_EQ(l["status"], "done");
  ASSERT_EQ(ReadRunLog(parts / "log-1-of-2.jsonl").size(), 1u);

  const SynthSummary merged = MergeSynthParts(KittiRequest(Dir(), Dir() / "sharded"));
  EXPECT_EQ(merged.frames, 3u);
  EXPECT_EQ(merged.objects, local_->objects);
  ExpectSameTree(Dir() / "local", Dir() / "sharded");
  EXPECT_TRUE(fs::exists(parts / "0-000000"));  // the merge leaves the parts

  // A rerun of a finished shard does nothing but log the skips.
  fs::copy(parts, SynthPartsDir(Dir() / "rerun"), fs::copy_options::recursive);
  const SynthShardSummary rerun = RunSynthShard(KittiRequest(Dir(), Dir() / "rerun"), ShardSpec{0, 2});
  EXPECT_EQ(rerun.done, 0u);
  EXPECT_EQ(rerun.skipped, 2u);
  const auto log = ReadRunLog(SynthPartsDir(Dir() / "rerun") / "log-0-of-2.jsonl");
  ASSERT_EQ(log.size(), 4u);  // appended
  EXPECT_EQ(log[2]["status"], "skipped");
  EXPECT_EQ(log[3]["status"], "skipped");
}

TEST_F(SynthBatchTest, MergeWithAMissingPartNamesTheFramesAndCreatesNothing) {
  const fs::path out = Dir() / "missing";
  fs::copy(SynthPartsDir(Dir() / "sharded"), SynthPartsDir(out), fs::copy_options::recursive);
  fs::remove_all(SynthPartsDir(out) / "1-000001");
  const std::string err = InputErrorOf([&] { MergeSynthParts(KittiRequest(Dir(), out)); });
  EXPECT_NE(err.find("no part for 1 of the 3 selected frame(s): 1 ("), std::string::npos) << err;
  EXPECT_FALSE(fs::exists(out));
  for (const auto& e : fs::directory_iterator(Dir())) EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << e.path();
}

TEST_F(SynthBatchTest, PartsOfAnotherScenarioAreRefused) {
  const fs::path out = Dir() / "other";
  fs::copy(SynthPartsDir(Dir() / "sharded"), SynthPartsDir(out), fs::copy_options::recursive);
  nlohmann::json scenario = ReadJsonFile(Dir() / "kitti.json");
  scenario["seed"] = 8;
  WriteJsonFile(Dir() / "seed8.json", scenario);
  SynthRequest r = KittiRequest(Dir(), out);
  r.scenario = Dir() / "seed8.json";
  std::string err = InputErrorOf([&] { MergeSynthParts(r); });
  EXPECT_NE(err.find("part of a different synth request (scenario_fnv1a64"), std::string::npos) << err;
  EXPECT_FALSE(fs::exists(out));
  // A shard does not mix its parts in either (before synthesising anything).
  err = InputErrorOf([&] { RunSynthShard(r, ShardSpec{0, 2}); });
  EXPECT_NE(err.find("part of a different synth request"), std::string::npos) << err;
  // Nor parts rendered with other settings.
  r = KittiRequest(Dir(), out);
  r.options.samples_per_pixel = 2;
  err = InputErrorOf([&] { MergeSynthParts(r); });
  EXPECT_NE(err.find("samples_per_pixel is 1, this run's is 2"), std::string::npos) << err;
}

// Parts of version 2 held their poses as {"q_wxyz", "t"} and their boxes as {"T_frame_box", "size"}; this build
// writes the shared geometry codec's layout as version 3. A part an older build left behind is refused by name,
// by the merge and by a resumed shard, never read in the wrong layout.
TEST_F(SynthBatchTest, PartsOfAnOlderLayoutAreRefused) {
  const fs::path out = Dir() / "older";
  fs::copy(SynthPartsDir(Dir() / "sharded"), SynthPartsDir(out), fs::copy_options::recursive);
  const fs::path part = SynthPartsDir(out) / "1-000001" / "part.json";
  nlohmann::json j = ReadJsonFile(part);
  EXPECT_EQ(j["version"], 3);
  ASSERT_FALSE(j["objects"].empty());
  const nlohmann::json& box = j["objects"][0]["box"];
  EXPECT_TRUE(box.contains("center") && box.contains("size") && box.contains("rotation_wxyz")) << box.dump();
  j["version"] = 2;
  WriteJsonFile(part, j, -1);
  std::string err = InputErrorOf([&] { MergeSynthParts(KittiRequest(Dir(), out)); });
  EXPECT_NE(err.find("1-000001/part.json: a synth part of version 2, this build reads version 3"), std::string::npos) << err;
  EXPECT_FALSE(fs::exists(out));
  err = InputErrorOf([&] { RunSynthShard(KittiRequest(Dir(), out), ShardSpec{1, 2}); });
  EXPECT_NE(err.find("a synth part of version 2"), std::string::npos) << err;
}

// synth.json records each object's whole box, the tilt the road gave it included, as the part holds it: the
// heading (yaw_ego_rad) alone would lay a box on a slope flat.
TEST_F(SynthBatchTest, SynthJsonHoldsEachObjectsWholeBox) {
  const nlohmann::json j = ReadJsonFile(Dir() / "local" / "synth.json");
  ASSERT_EQ(j["frames"].size(), 3u);
  size_t objects = 0;
  double largest_tilt = 0;
  for (size_t f = 0; f < j["frames"].size(); ++f) {
    const nlohmann::json& jf = j["frames"][f];
    const fs::path part = SynthPartsDir(Dir() / "sharded") /
                          (std::to_string(f) + "-" + jf["token"].get<std::string>()) / "part.json";
    const nlohmann::json part_json = ReadJsonFile(part);
    const JsonReader objects_of_part = JsonReader(part_json, part)["objects"];
    ASSERT_EQ(jf["objects"].size(), objects_of_part.Size()) << part;
    for (size_t k = 0; k < jf["objects"].size(); ++k, ++objects) {
      const Box3 written = ReadBox3(JsonReader(jf["objects"][k], "synth.json")["box_ego"]);
      const Box3 placed = ReadBox3(objects_of_part[k]["box"]);
      EXPECT_EQ(written.T_frame_box.translation, placed.T_frame_box.translation);
      EXPECT_EQ(written.T_frame_box.rotation.coeffs(), placed.T_frame_box.rotation.coeffs());
      EXPECT_EQ(written.size, placed.size);
      EXPECT_NEAR(written.Yaw(), jf["objects"][k]["yaw_ego_rad"].get<double>(), 1e-12);
      const Eigen::Vector3d up = written.T_frame_box.Rotation().col(2);
      largest_tilt = std::max(largest_tilt, std::acos(std::clamp(up.z(), -1.0, 1.0)));
    }
  }
  EXPECT_GT(objects, 0u);
  EXPECT_GT(largest_tilt, 1e-4) << "no object tilted with its road: the test shows nothing";
}

// Realism is the default: each frame's model, fitted from its own HDL-64E sweep (KITTI: record-order lasers,
// clockwise forced), is named in synth.json; KITTI object frames have no neighbours, so no ego motion. Parts of
// the ideal sensor (--no-lidar-realism) are of another request.
TEST_F(SynthBatchTest, SynthJsonNamesEachFramesLidarModel) {
  const nlohmann::json j = ReadJsonFile(Dir() / "local" / "synth.json");
  ASSERT_EQ(j["frames"].size(), 3u);
  for (const auto& f : j["frames"]) {
    const std::string m = f["lidar_model"].get<std::string>();
    EXPECT_EQ(m.find("64 lasers (inferred)"), 0u) << m;
    EXPECT_NE(m.find(" Hz cw;"), std::string::npos) << m;
    EXPECT_EQ(f["lidar_ego_motion"], false);
  }
  SynthRequest r = KittiRequest(Dir(), Dir() / "ideal");
  fs::copy(SynthPartsDir(Dir() / "sharded"), SynthPartsDir(r.out), fs::copy_options::recursive);
  r.options.lidar_realism = false;
  const std::string err = InputErrorOf([&] { MergeSynthParts(r); });
  EXPECT_NE(err.find("lidar_realism is true, this run's is false"), std::string::npos) << err;
  fs::remove_all(SynthPartsDir(r.out));
  // The ideal sensor's run: "off", the same labels' boxes and images, another sweep.
  r.options.frames = {"000001"};
  RunSynth(r);
  const nlohmann::json ji = ReadJsonFile(r.out / "synth.json");
  ASSERT_EQ(ji["frames"].size(), 1u);
  EXPECT_EQ(ji["frames"][0]["lidar_model"], "off");
  EXPECT_EQ(ji["frames"][0]["objects"].size(), j["frames"][1]["objects"].size());
  for (size_t k = 0; k < ji["frames"][0]["objects"].size(); ++k)
    EXPECT_EQ(ji["frames"][0]["objects"][k]["center_ego_m"], j["frames"][1]["objects"][k]["center_ego_m"]);
  EXPECT_EQ(ReadFileToString(r.out / "image_2" / "000001.png"), ReadFileToString(Dir() / "local" / "image_2" / "000001.png"));
  EXPECT_NE(ReadFileToString(r.out / "velodyne" / "000001.bin"), ReadFileToString(Dir() / "local" / "velodyne" / "000001.bin"));
}

// Shards + merge equal a local run by construction, because a local run goes through parts too; this checks
// that the parts lose nothing: the dataset and report written straight from the in-memory outcomes (the way
// RunSynth wrote them before parts existed) are the bytes RunSynth writes. On KITTI (labels with 2-6
// decimals) and on the nuScenes mmdet3d info (labels as full-precision JSON doubles).
void ExpectPartsLoseNothing(const SynthRequest& r, const fs::path& direct) {
  const Log log = OpenLog(r.log);
  std::vector<Asset> assets;
  for (const auto& a : r.assets) assets.push_back(LoadAsset(a));
  const Scenario scenario = ReadScenario(r.scenario);
  std::vector<FrameOutcome> outcomes;
  std::vector<FrameEdit> edits;
  for (size_t i = 0; i < log.frames.size(); ++i) {
    outcomes.push_back(SynthesizeFrame(log, i, assets, scenario, r.options));
    edits.push_back(outcomes.back().edit);
  }
  fs::create_directories(direct);
  WriteDerivative(log, edits, direct, r.options.write);
  WriteSynthReport(log, outcomes, assets, direct / "report.html");
  fs::copy_file(r.out / "synth.json", direct / "synth.json");  // written by RunSynth only
  ExpectSameTree(r.out, direct);
}

TEST_F(SynthBatchTest, PartsLoseNothingKitti) {
  ExpectPartsLoseNothing(KittiRequest(Dir(), Dir() / "local"), Dir() / "direct_kitti");
}

TEST_F(SynthBatchTest, PartsLoseNothingNuScenesMmdet3d) {
  SynthRequest r = KittiRequest(Dir(), Dir() / "nuscenes");
  r.log = testing::RepoData("driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json");
  r.scenario = testing::RepoData("scenarios/demo.json");
  const SynthSummary s = RunSynth(r);
  EXPECT_EQ(s.objects, 5u);
  ExpectPartsLoseNothing(r, Dir() / "direct_nuscenes");
}

// The crash test's child (run by KilledShardResumes through exec of this binary): a shard whose hook stops
// for good half way through frame 1's part, until the parent kills it.
TEST(SynthCrashChild, ShardHangingMidPart) {
  const char* dir = std::getenv(kCrashChildEnv);
  if (!dir) GTEST_SKIP() << "only run by SynthBatchTest.KilledShardResumesAndMergesToTheSameResult";
  SynthRequest r = KittiRequest(dir, fs::path(dir) / "killed");
  r.options.part_written_hook = [&](size_t frame, const fs::path& staging) {
    if (frame != 1) return;
    WriteFileAtomic(fs::path(dir) / "hook_reached", staging.string());
    std::this_thread::sleep_for(std::chrono::hours(1));
  };
  RunSynthShard(r, ShardSpec{0, 1});
  FAIL() << "the shard was not killed";
}

TEST_F(SynthBatchTest, KilledShardResumesAndMergesToTheSameResult) {
  const fs::path out = Dir() / "killed", parts = SynthPartsDir(out);
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    setenv(kCrashChildEnv, Dir().c_str(), 1);
    execl("/proc/self/exe", "batch_test", "--gtest_filter=SynthCrashChild.*", static_cast<char*>(nullptr));
    _exit(127);
  }
  // Wait for the hook (no time limit of our own: CTest's timeout bounds a hung child).
  int status = 0;
  bool exited = false;
  while (!fs::exists(Dir() / "hook_reached")) {
    if (waitpid(pid, &status, WNOHANG) == pid) {
      exited = true;
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ASSERT_FALSE(exited) << "child exited before its hook, status " << status;
  ASSERT_EQ(kill(pid, SIGKILL), 0);
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);

  // Frame 0's part is complete; frame 1 has only a staging folder, with the sweep but no part.json.
  EXPECT_TRUE(fs::exists(parts / "0-000000" / "part.json"));
  EXPECT_FALSE(fs::exists(parts / "1-000001"));
  const fs::path staging = ReadFileToString(Dir() / "hook_reached");
  EXPECT_EQ(staging.parent_path(), parts);
  EXPECT_EQ(staging.filename().string().rfind("1-000001.tmp-", 0), 0u) << staging;
  EXPECT_TRUE(fs::exists(staging / "sweep.bin"));
  EXPECT_FALSE(fs::exists(staging / "part.json"));
  EXPECT_FALSE(fs::exists(out));

  // The merge refuses; the rerun cleans the staging folder up, skips frame 0 and finishes 1 and 2.
  const std::string err = InputErrorOf([&] { MergeSynthParts(KittiRequest(Dir(), out)); });
  EXPECT_NE(err.find("selected frame(s): 1, 2 ("), std::string::npos) << err;
  const SynthShardSummary rerun = RunSynthShard(KittiRequest(Dir(), out), ShardSpec{0, 1});
  EXPECT_EQ(rerun.skipped, 1u);
  EXPECT_EQ(rerun.done, 2u);
  EXPECT_FALSE(fs::exists(staging));
  for (const auto& e : fs::directory_iterator(parts)) EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << e.path();
  const auto log = ReadRunLog(parts / "log-0-of-1.jsonl");
  ASSERT_EQ(log.size(), 4u);  // the killed run's frame 0, then the rerun's three frames
  EXPECT_EQ(log[1]["status"], "skipped");
  EXPECT_EQ(log[2]["status"], "done");
  MergeSynthParts(KittiRequest(Dir(), out));
  ExpectSameTree(Dir() / "local", out);
}

TEST_F(SynthBatchTest, AFailingFrameDoesNotStopTheOthers) {
  // A copy of the log whose frame 1 sweep is truncated mid-record.
  const fs::path log = Dir() / "kitti_bad";
  fs::copy(testing::RepoData("driving/kitti-object"), log, fs::copy_options::recursive);
  const fs::path sweep = log / "training/velodyne/000001.bin";
  fs::permissions(sweep, fs::perms::owner_write, fs::perm_options::add);
  fs::resize_file(sweep, 1003);
  SynthRequest r = KittiRequest(Dir(), Dir() / "bad_out");
  r.log = log;
  r.options.frames = {"1", "0"};
  const SynthShardSummary s = RunSynthShard(r, ShardSpec{0, 1});
  EXPECT_EQ(s.done, 1u);
  EXPECT_EQ(s.failed, std::vector<size_t>{1});
  EXPECT_TRUE(fs::exists(s.parts / "0-000000" / "part.json"));
  const auto lines = ReadRunLog(s.run_log);
  ASSERT_EQ(lines.size(), 2u);
  EXPECT_EQ(lines[0]["frame"], 1);
  EXPECT_EQ(lines[0]["status"], "failed");
  EXPECT_NE(lines[0]["error"].get<std::string>().find("000001.bin: size 1003 B is not a whole number"), std::string::npos) << lines[0];
  EXPECT_EQ(lines[1]["frame"], 0);
  EXPECT_EQ(lines[1]["status"], "done");
  EXPECT_GT(lines[1]["seconds"].get<double>(), 0.0);
  const std::string err = InputErrorOf([&] { MergeSynthParts(r); });
  EXPECT_NE(err.find("selected frame(s): 1 ("), std::string::npos) << err;

  // A local run of the failing frame alone rethrows its error and leaves nothing behind.
  r.out = Dir() / "bad_local";
  r.options.frames = {"1"};
  const std::string local_err = InputErrorOf([&] { RunSynth(r); });
  EXPECT_NE(local_err.find("not a whole number of 16-byte records"), std::string::npos) << local_err;
  EXPECT_FALSE(fs::exists(r.out));
  EXPECT_FALSE(fs::exists(SynthPartsDir(r.out)));
}


// World-fixed scenarios (one plan per sequence; each KITTI object frame is its own sequence): every shard
// computes the same plan from the whole selection, so shards + merge still write a local run's bytes, plan.json
// and coco_2d.json included.
TEST(SynthBatchWorldFixed, ShardsAndAMergeWriteTheSameBytesAsALocalRunWithPlanAndCoco) {
  testing::TempDir dir;
  testing::ImportDemoAssets(dir.path());
  nlohmann::json scenario = nlohmann::json::parse(kKittiScenario);
  scenario["world_fixed"] = true;
  WriteFileAtomic(dir / "kitti.json", scenario.dump());
  SynthRequest local = KittiRequest(dir.path(), dir / "local");
  local.options.coco = true;
  const SynthSummary s = RunSynth(local);
  EXPECT_EQ(s.frames, 3u);
  SynthRequest sharded = KittiRequest(dir.path(), dir / "sharded");
  sharded.options.coco = true;
  RunSynthShard(sharded, ShardSpec{1, 2});
  RunSynthShard(sharded, ShardSpec{0, 2});
  const SynthSummary merged = MergeSynthParts(sharded);
  EXPECT_EQ(merged.objects, s.objects);
  ExpectSameTree(dir / "local", dir / "sharded");

  // plan.json: one sequence per KITTI frame, 4 objects each; synth.json ties every label to its plan object.
  const nlohmann::json plan = ReadJsonFile(dir / "local" / "plan.json");
  ASSERT_EQ(plan["sequences"].size(), 3u);
  for (const auto& seq : plan["sequences"]) {
    EXPECT_EQ(seq["objects"].size(), 4u);
    EXPECT_EQ(seq["surface"], "road_surface");
  }
  const nlohmann::json synth = ReadJsonFile(dir / "local" / "synth.json");
  size_t labelled = 0;
  for (size_t f = 0; f < 3; ++f)
    for (const auto& o : synth["frames"][f]["objects"]) {
      ++labelled;
      const auto& po = plan["sequences"][f]["objects"][o["plan_object"].get<size_t>()];
      EXPECT_EQ(po["asset"], o["asset"]);
      for (int c = 0; c < 3; ++c)  // KITTI: world = ego frame
        EXPECT_NEAR(o["center_world_m"][c].get<double>(), o["center_ego_m"][c].get<double>(), 1e-9);
    }
  EXPECT_EQ(labelled, s.objects);

  // coco_2d.json: the real KITTI 2D boxes plus one synthetic box per inserted object the camera sees.
  const Coco2D coco = ReadCoco2D(dir / "local" / "coco_2d.json");
  EXPECT_EQ(coco.images.size(), 3u);
  size_t synthetic = 0;
  for (const CocoAnnotation& a : coco.annotations) {
    if (!a.synthetic) continue;
    ++synthetic;
    EXPECT_TRUE(a.asset_id == "cone" || a.asset_id == "barrier" || a.asset_id == "car") << a.asset_id;
    EXPECT_GT(a.area, 0);
    EXPECT_GE(a.box.x1, 0);
    EXPECT_LE(a.box.x2, 1242);
  }
  EXPECT_GT(synthetic, 0u);
  EXPECT_LE(synthetic, s.objects);

  // Parts made for another selection were made under another plan: the merge refuses them, naming the plan.
  SynthRequest two = KittiRequest(dir.path(), dir / "other");
  two.options.frames = {"0", "1"};
  RunSynthShard(two, ShardSpec{0, 1});
  SynthRequest one = KittiRequest(dir.path(), dir / "other");
  one.options.frames = {"0"};
  const std::string err = InputErrorOf([&] { MergeSynthParts(one); });
  EXPECT_NE(err.find("part of a different synth request (plan_fnv1a64 is"), std::string::npos) << err;
  EXPECT_FALSE(fs::exists(dir / "other"));
}
}  // namespace
}  // namespace sd
