#include "datasets/categories.h"

#include <algorithm>
#include <cctype>

#include "datasets/format.h"

namespace sd {

namespace {
std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}
}  // namespace

const std::vector<CategoryInfo>& Categories() {
  // Sizes (length, width, height, m): nuScenes training-set means for the 10 detection classes; typical
  // product dimensions for the rare objects (EU warning triangle, folding A-frame sign, a fallen crate /
  // tyre-sized debris, a trailer-mounted portable traffic light). Reflectivity: relative to asphalt,
  // rough guesses (retro-reflective objects high) for LiDAR simulation.
  static const std::vector<CategoryInfo> kCategories = {
      {"car", {4.63, 1.97, 1.74}, "vehicle.car", "Car", "Car", 2.0},
      {"truck", {6.94, 2.51, 2.84}, "vehicle.truck", "Truck", "Medium-sized Truck", 2.0},
      {"trailer", {12.29, 2.90, 3.87}, "vehicle.trailer", "Trailer", "Towed Object", 2.0},
      {"bus", {11.0, 2.94, 3.47}, "vehicle.bus.rigid", "Bus", "Bus", 2.0},
      {"construction_vehicle", {6.37, 2.85, 3.19}, "vehicle.construction", "ConstructionVehicle", "Other Vehicle - Construction Vehicle", 1.8},
      {"bicycle", {1.70, 0.60, 1.28}, "vehicle.bicycle", "Cyclist", "Bicycle", 1.2},
      {"motorcycle", {2.11, 0.77, 1.47}, "vehicle.motorcycle", "Motorcycle", "Motorcycle", 1.5},
      {"pedestrian", {0.73, 0.67, 1.77}, "human.pedestrian.adult", "Pedestrian", "Pedestrian", 1.0},
      {"traffic_cone", {0.41, 0.41, 1.07}, "movable_object.trafficcone", "TrafficCone", "Cones", 3.0},
      {"barrier", {2.53, 0.50, 0.98}, "movable_object.barrier", "Barrier", "Temporary Construction Barriers", 2.5},
      {"warning_tripod", {0.45, 0.30, 0.45}, "movable_object.warning_tripod", "WarningTripod", "Warning Tripod", 4.0},
      {"a_frame_sign", {0.60, 0.55, 1.00}, "movable_object.a_frame_sign", "AFrameSign", "Construction Signs", 2.5},
      {"debris", {0.80, 0.60, 0.40}, "movable_object.debris", "Debris", "Debris", 0.8},
      {"portable_traffic_light", {1.20, 1.00, 3.00}, "movable_object.portable_traffic_light", "PortableTrafficLight", "Portable Traffic Light", 2.5},
  };
  return kCategories;
}

std::optional<CategoryInfo> FindCategory(const std::string& name) {
  const std::string n = Lower(name);
  for (const CategoryInfo& c : Categories())
    if (n == c.name || n == Lower(c.nuscenes_name) || n == Lower(c.kitti_name) || n == Lower(c.pandaset_name)) return c;
  // Other spellings seen in the datasets we read.
  static const std::vector<std::pair<std::string, std::string>> kAliases = {
      {"van", "car"},
      {"human.pedestrian.child", "pedestrian"},
      {"human.pedestrian.construction_worker", "pedestrian"},
      {"human.pedestrian.police_officer", "pedestrian"},
      {"person_sitting", "pedestrian"},
      {"vehicle.bus.bendy", "bus"},
      {"movable_object.debris", "debris"},
      {"traffic cone", "traffic_cone"},
      {"trafficcone", "traffic_cone"},
      // Argoverse 2 sensor-dataset classes with a canonical counterpart of the same shape (TRUCK, BUS,
      // BICYCLE, MOTORCYCLE, PEDESTRIAN match canonical names already). The rest stay unmapped: BOLLARD is a
      // fixed post, not a 2.5 m barrier; CONSTRUCTION_BARREL, STROLLER, SIGN, ...
      {"regular_vehicle", "car"},
      {"large_vehicle", "truck"},
      {"box_truck", "truck"},
      {"truck_cab", "truck"},
      {"vehicular_trailer", "trailer"},
      {"articulated_bus", "bus"},
      {"school_bus", "bus"},
      {"bicyclist", "bicycle"},
      {"motorcyclist", "motorcycle"},
      {"official_signaler", "pedestrian"},
      {"construction_cone", "traffic_cone"},
      {"mobile_pedestrian_crossing_sign", "a_frame_sign"},
      // PandaSet cuboid labels (the semantic classes of annotations/semseg/classes.json) beside the canonical
      // ones it writes. Pickup trucks are cars, as in nuScenes; Pylons (delineator posts), Signs, Emergency
      // Vehicle, scooters and the rest stay unmapped.
      {"pickup truck", "car"},
      {"semi-truck", "truck"},
      {"pedestrian with object", "pedestrian"},
      {"road barriers", "barrier"},
  };
  for (const auto& [alias, canonical] : kAliases)
    if (n == alias) return FindCategory(canonical);
  return std::nullopt;
}

std::string DatasetCategoryName(const CategoryInfo& category, LogFormat format) {
  return FormatInfo(format).class_name(category);
}

std::string CanonicalCategory(const std::string& name) {
  const auto category = FindCategory(name);
  return category ? category->name : name;
}

}  // namespace sd
