// What OpenLog refuses or reports whatever the format: samples listed twice, sensor files shared by two samples,
// paths leading outside the data root, images of another size than their calibration or their channel's others,
// and fields a reader had to default. Each case is the repo's nuScenes keyframe info with one thing changed, read
// where the keyframe's files are, so that only that one thing is wrong.
#include <gtest/gtest.h>

#include <functional>
#include <sstream>
#include <string>

#include "core/error.h"
#include "datasets/readers.h"
#include "io/files.h"
#include "io/image_io.h"
#include "io/json.h"
#include "testing/testing.h"

namespace sd {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using sd::testing::RepoData;
using sd::testing::TempDir;

const char* kKf0 = "driving/nuscenes-scene0061-kf0";
const char* kKf0Info = "driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json";

// The InputError message of opening `info` under `data_root`, or "" when it opened.
std::string OpenError(const fs::path& info, const fs::path& data_root) {
  try {
    OpenLogOptions options;
    options.data_root = data_root;
    OpenLog(info, options);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

struct Broken {
  const char* name;
  std::function<void(json&)> corrupt;
  std::vector<const char*> expected;  // fragments of the one-line error
};

void ExpectRefused(const std::vector<Broken>& cases) {
  TempDir tmp;
  const json original = ReadJsonFile(RepoData(kKf0Info));
  for (const Broken& c : cases) {
    json broken = original;
    c.corrupt(broken);
    const fs::path file = tmp / (std::string("broken_") + c.name + ".json");
    WriteJsonFile(file, broken);
    const std::string message = OpenError(file, RepoData(kKf0));
    EXPECT_NE(message.find(file.filename().string()), std::string::npos) << c.name << ": '" << message << "'";
    for (const char* fragment : c.expected) EXPECT_NE(message.find(fragment), std::string::npos) << c.name << ": " << message;
    EXPECT_EQ(message.find('\n'), std::string::npos) << c.name << ": " << message;
  }
}

TEST(ReaderChecks, EachSampleAndEachSensorFileOnce) {
  ExpectRefused({
      {"sample_twice", [](json& d) { d["data_list"].push_back(d["data_list"][0]); },
       {"frame 1", "listed twice", "also frame 0"}},
      // Another token, the same recording: still one sweep and six images made into two samples.
      {"same_files",
       [](json& d) {
         json again = d["data_list"][0];
         again["token"] = "another-token";
         d["data_list"].push_back(again);
       },
       {"frame another-token", "LIDAR_TOP's file", "one recording cannot be two samples"}},
  });
}

TEST(ReaderChecks, PathsLeadingOutsideTheDataRootAreRefused) {
  ExpectRefused({
      {"absolute", [](json& d) { d["data_list"][0]["images"]["CAM_FRONT"]["img_path"] = "/etc/passwd"; },
       {"CAM_FRONT's path '/etc/passwd' leads outside the data root", "--data-root"}},
      {"nul", [](json& d) { d["data_list"][0]["images"]["CAM_BACK"]["img_path"] = std::string("samples/CAM_BACK/a.jpg") + '\0' + "/../x"; },
       {"CAM_BACK's path holds a NUL character"}},
      {"dotdot",
       [](json& d) { d["data_list"][0]["lidar_points"]["lidar_path"] = "samples/LIDAR_TOP/../../../../../../etc/passwd"; },
       {"LIDAR_TOP's path", "leads outside the data root"}},
  });
  // Naming a root that holds it is how a user allows a path: the error is then about the file itself.
  TempDir tmp;
  json info = ReadJsonFile(RepoData(kKf0Info));
  info["data_list"][0]["images"]["CAM_FRONT"]["img_path"] = "/nonexistent-synthdrive-dir/cam.jpg";
  WriteJsonFile(tmp / "info.json", info);
  const std::string message = OpenError(tmp / "info.json", "/");
  EXPECT_EQ(message.find("outside the data root"), std::string::npos) << message;
}

TEST(ReaderChecks, FieldsThatCannotBeGuessedAreRefused) {
  ExpectRefused({
      {"num_pts_feats_string", [](json& d) { d["data_list"][0]["lidar_points"]["num_pts_feats"] = "5"; },
       {"lidar_points.num_pts_feats"}},
      {"num_pts_feats_six", [](json& d) { d["data_list"][0]["lidar_points"]["num_pts_feats"] = 6; },
       {"lidar_points.num_pts_feats", "6 features per point"}},
      {"box_size_null", [](json& d) { d["data_list"][0]["instances"][0]["bbox_3d"][3] = nullptr; },
       {"frame ", "annotation 0", "impossible box size (nan, 0.621, 1.642)"}},
      {"box_far", [](json& d) { d["data_list"][0]["instances"][2]["bbox_3d"][0] = 1e308; },
       {"annotation 2", "impossible box centre"}},
      {"camera_without_image", [](json& d) { d["data_list"][0]["images"]["CAM_BACK"].erase("img_path"); },
       {"images.CAM_BACK", "a camera without img_path"}},
      {"cam2img_skew", [](json& d) { d["data_list"][0]["images"]["CAM_FRONT"]["cam2img"][0][1] = 30.0; },
       {".data_list[0].images.CAM_FRONT.cam2img: a skewed camera matrix (K[0][1] = 30"}},
      {"timestamp_nan", [](json& d) { d["data_list"][0]["timestamp"] = nullptr; },
       {".data_list[0].timestamp: NaN or null: not a time"}},
      {"timestamp_huge", [](json& d) { d["data_list"][0]["timestamp"] = 1e300; },
       {"frame ", "impossible timestamp 1e+300 s"}},
  });
}

// KITTI's text files, each corrupted in a copy of the repo's three frames: the calib matrices, a missing image,
// a label's numbers. Before, NaN calibrations and labels flowed into the geometry and a missing image silently
// made its frame LiDAR-only.
TEST(ReaderChecks, KittiCalibImagesAndLabelsAreChecked) {
  TempDir tmp;
  const fs::path original = RepoData("driving/kitti-object");
  struct Case {
    const char* name;
    std::function<void(const fs::path& training)> corrupt;
    const char* expected;
  };
  // Replaces the numbers of `key`'s line in frame 000001's calib (or label, when key is "Car" etc.).
  auto set_line = [](const fs::path& file, const std::string& key, const std::string& numbers) {
    std::istringstream in(ReadFileToString(file));
    std::string out, line;
    while (std::getline(in, line)) out += (line.rfind(key, 0) == 0 ? key + " " + numbers : line) + "\n";
    WriteFileAtomic(file, out);
  };
  const std::vector<Case> cases = {
      {"p2_nan", [&](const fs::path& t) { set_line(t / "calib/000001.txt", "P2:", "nan 0 600 0 0 707 180 0 0 0 1 0"); },
       "not a finite number"},
      {"p2_zero_focal", [&](const fs::path& t) { set_line(t / "calib/000001.txt", "P2:", "0 0 600 0 0 707 180 0 0 0 1 0"); },
       "P2: impossible focal lengths fx = 0"},
      {"p2_skew", [&](const fs::path& t) { set_line(t / "calib/000001.txt", "P2:", "707 5 600 0 0 707 180 0 0 0 1 0"); },
       "P2: a skewed camera matrix (K[0][1] = 5"},
      {"p2_bottom_row", [&](const fs::path& t) { set_line(t / "calib/000001.txt", "P2:", "707 0 600 0 0 707 180 0 0 0 0 0"); },
       "P2: not a camera matrix"},
      {"r0_scaled", [&](const fs::path& t) { set_line(t / "calib/000001.txt", "R0_rect:", "2 0 0 0 2 0 0 0 2"); },
       "R0_rect: the rotation is not orthonormal (R^T R differs from I by 3)"},
      {"tr_reflection", [&](const fs::path& t) { set_line(t / "calib/000001.txt", "Tr_velo_to_cam:", "1 0 0 0 0 1 0 0 0 0 -1 0"); },
       "Tr_velo_to_cam: the rotation is a reflection"},
      {"tr_far", [&](const fs::path& t) { set_line(t / "calib/000001.txt", "Tr_velo_to_cam:", "1 0 0 0 0 1 0 0 0 0 1 1e17"); },
       "Tr_velo_to_cam: the translation is 1e+17 m"},
      {"image_missing", [](const fs::path& t) { fs::remove(t / "image_2/000001.png"); }, "missing KITTI image"},
      {"label_nan", [&](const fs::path& t) { set_line(t / "label_2/000001.txt", "Truck", "0.00 0 -1.57 599.41 156.40 629.75 189.25 2.85 nan 5.12 4.59 1.32 45.84 -1.55"); },
       "field 10 is not a finite number"},
      {"label_zero_size", [&](const fs::path& t) { set_line(t / "label_2/000001.txt", "Truck", "0.00 0 -1.57 599.41 156.40 629.75 189.25 2.85 0 5.12 4.59 1.32 45.84 -1.55"); },
       "impossible dimensions h w l = 2.85 0 5.12"},
  };
  for (const Case& c : cases) {
    const fs::path root = tmp / c.name;
    fs::copy(original, root, fs::copy_options::recursive);
    c.corrupt(root / "training");
    std::string message;
    try {
      OpenLog(root);
    } catch (const InputError& e) {
      message = e.what();
    }
    EXPECT_NE(message.find("000001"), std::string::npos) << c.name << ": '" << message << "'";
    EXPECT_NE(message.find(c.expected), std::string::npos) << c.name << ": '" << message << "'";
    EXPECT_EQ(message.find('\n'), std::string::npos) << c.name << ": " << message;
  }
  EXPECT_NO_THROW(OpenLog(original));
}

TEST(ReaderChecks, DefaultedFieldsAreReportedOnce) {
  TempDir tmp;
  json info = ReadJsonFile(RepoData(kKf0Info));
  info["data_list"][0].erase("ego2global");
  for (auto& [channel, cam] : info["data_list"][0]["images"].items()) cam.erase("lidar2cam");
  WriteJsonFile(tmp / "info.json", info);
  OpenLogOptions options;
  options.data_root = RepoData(kKf0);
  const Log log = OpenLog(tmp / "info.json", options);
  ASSERT_EQ(log.assumptions.size(), 2u);
  EXPECT_NE(log.assumptions[0].find("ego2global missing: the ego pose taken as the world origin"), std::string::npos);
  EXPECT_NE(log.assumptions[0].find("in 1 of 1 frames"), std::string::npos) << log.assumptions[0];
  // Six cameras without lidar2cam are one frame, one line.
  EXPECT_NE(log.assumptions[1].find("lidar2cam missing"), std::string::npos);
  EXPECT_NE(log.assumptions[1].find("in 1 of 1 frames"), std::string::npos) << log.assumptions[1];
  EXPECT_FALSE(log.sequential);
  EXPECT_TRUE(OpenLog(RepoData(kKf0Info)).assumptions.empty());
}

// Images whose size is not the calibration's: cropped so that the principal point still lies inside but far from
// the centre, and (two frames) one CAM_FRONT image of another size than the other's with the principal point
// still central. Both used to be accepted and drew objects through the wrong camera.
TEST(ReaderChecks, ImagesOfAnotherSizeThanTheirCalibrationAreRefused) {
  TempDir tmp;
  const json original = ReadJsonFile(RepoData(kKf0Info));
  const std::string front = original["data_list"][0]["images"]["CAM_FRONT"]["img_path"].get<std::string>();
  const ImageU8 full = ReadImage(RepoData(kKf0) / "samples" / "CAM_FRONT" / fs::path(front).filename(), 3);
  auto top_rows = [&](int rows) {
    ImageU8 cut(full.width(), rows, 3);
    for (int y = 0; y < rows; ++y)
      for (int x = 0; x < full.width(); ++x)
        for (int c = 0; c < 3; ++c) cut.at(x, y, c) = full.at(x, y, c);
    return cut;
  };
  const fs::path cropped_root = tmp / "cropped";
  WriteImage(cropped_root / "samples" / "CAM_FRONT" / fs::path(front).filename(), top_rows(600));
  const std::string cropped = OpenError(RepoData(kKf0Info), cropped_root);
  EXPECT_NE(cropped.find("CAM_FRONT.cam2img: the principal point"), std::string::npos) << cropped;
  EXPECT_NE(cropped.find("far from the centre of the 1600x600 image"), std::string::npos) << cropped;

  // nuScenes' calibration for 1600x900 with CAM_FRONT padded to 1920x1080: the principal point, at 43 % and 46 %,
  // passes the general check; every nuScenes v1.0 camera image is 1600x900.
  const fs::path padded_root = tmp / "padded";
  fs::create_directories(padded_root);
  fs::copy(RepoData(kKf0) / "samples", padded_root / "samples", fs::copy_options::recursive);
  ImageU8 padded(1920, 1080, 3);
  for (int y = 0; y < full.height(); ++y)
    for (int x = 0; x < full.width(); ++x)
      for (int c = 0; c < 3; ++c) padded.at(x, y, c) = full.at(x, y, c);
  WriteImage(padded_root / "samples" / "CAM_FRONT" / fs::path(front).filename(), padded);
  const std::string wider = OpenError(RepoData(kKf0Info), padded_root);
  EXPECT_NE(wider.find("camera CAM_FRONT's image"), std::string::npos) << wider;
  EXPECT_NE(wider.find("is 1920x1080, but its calibration (principal point"), std::string::npos) << wider;
  EXPECT_NE(wider.find("is nuScenes' for 1600x900 images"), std::string::npos) << wider;

  // Frame 2: the same calibration with its own copies of the files, CAM_FRONT's cut to 1600x800 (principal point
  // at 61 % of the height: near enough the centre to pass on its own).
  const fs::path two_root = tmp / "two";
  fs::create_directories(two_root);
  fs::copy(RepoData(kKf0) / "samples", two_root / "samples", fs::copy_options::recursive);
  json two = original;
  json second = original["data_list"][0];
  second["token"] = "second";
  auto renamed = [](const std::string& p) { return fs::path(p).parent_path() / ("second_" + fs::path(p).filename().string()); };
  const std::string lidar = second["lidar_points"]["lidar_path"].get<std::string>();
  fs::copy_file(two_root / "samples" / "LIDAR_TOP" / fs::path(lidar).filename(),
                two_root / "samples" / "LIDAR_TOP" / renamed(lidar).filename());
  second["lidar_points"]["lidar_path"] = renamed(lidar).string();
  for (auto& [channel, cam] : second["images"].items()) {
    const std::string img = cam["img_path"].get<std::string>();
    const fs::path dir = two_root / "samples" / channel;
    if (channel == "CAM_FRONT") WriteImage(dir / renamed(img).filename(), top_rows(800));
    else fs::copy_file(dir / fs::path(img).filename(), dir / renamed(img).filename());
    cam["img_path"] = renamed(img).string();
  }
  two["data_list"].push_back(second);
  WriteJsonFile(tmp / "two.json", two);
  const std::string mixed = OpenError(tmp / "two.json", two_root);
  EXPECT_NE(mixed.find("frame second: camera CAM_FRONT's image"), std::string::npos) << mixed;
  EXPECT_NE(mixed.find("is 1600x800 where frame"), std::string::npos) << mixed;
  EXPECT_NE(mixed.find("of the same calibration, is 1600x900"), std::string::npos) << mixed;
}

}  // namespace
}  // namespace sd
