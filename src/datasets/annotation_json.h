#pragma once
// An Annotation (log.h) as JSON: SynthDrive's own record of one, as synth parts store their labels. Not a
// dataset's format: each dataset's writer keeps its own (nuScenes sample_annotation, mmdet3d instances).
//
//   {"category": str, "box": Box3 (io/geometry_json.h, ego frame), "token": str, "instance_token": str,
//    "num_lidar_pts": int, "velocity": [vx, vy] m/s, "visibility": int, "truncation": number,
//    "box2d_by_camera": {channel: Box2}, "detected": bool}
//
// Unknown values stay what Annotation uses for them: -1, or NaN, which is written as null and read back as NaN
// (velocity and truncation only; null anywhere else is refused). Every double round-trips bit for bit.
#include <nlohmann/json.hpp>

#include "datasets/log.h"
#include "io/json.h"

namespace sd {

nlohmann::json AnnotationJson(const Annotation& a);
// InputError naming the file and key for a missing field or a bad box (io/geometry_json.h's refusals).
Annotation ReadAnnotation(const JsonReader& r);

}  // namespace sd
