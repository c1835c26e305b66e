#pragma once
// JSON for the core geometry types: one encoding per type, the same in every file that holds one (synth parts,
// mining items, sequence plans), read through JsonReader so a bad value is named by file and JSON path.
//
//   Rigid3d T_a_b  {"translation": [x, y, z], "rotation_wxyz": [w, x, y, z]}     maps b into a; metres
//   Box3           {"center": [x, y, z], "size": [length, width, height], "rotation_wxyz": [w, x, y, z]}
//                  center + rotation = T_frame_box (core/box3.h); metres
//   Box2           [x1, y1, x2, y2]                                                 pixels
//
// Doubles are written in nlohmann's shortest round-trip form, so a finite value reads back bit for bit.
// Rotations: a quaternion within kUnitQuaternionTolerance of unit length is kept as written
// (Rigid3d::FromUnitQuaternion). Every rotation this codec writes is one, so our own files round-trip exactly;
// normalising again would move the last bit of about a third of them. Any other quaternion (hand-written, a few
// digits) is normalised (Rigid3d::FromWxyz); one shorter than 1e-6 names no rotation and is refused.
// Refused with an InputError naming the file and key: an array of the wrong length, a non-number (null included:
// geometry has no unknown values), a Box3 size that is not positive.
#include <nlohmann/json.hpp>

#include "core/box3.h"
#include "core/rigid3.h"
#include "io/json.h"

namespace sd {

// Far above the few ulps a unit quaternion's length is off by, far below what a quaternion printed to 6-9 digits is.
inline constexpr double kUnitQuaternionTolerance = 1e-12;

nlohmann::json Rigid3dJson(const Rigid3d& T);
Rigid3d ReadRigid3d(const JsonReader& r);

nlohmann::json Box3Json(const Box3& box);
Box3 ReadBox3(const JsonReader& r);

nlohmann::json Box2Json(const Box2& box);
Box2 ReadBox2(const JsonReader& r);

}  // namespace sd
