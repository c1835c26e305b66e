#include "assetgen/mined.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "io/image_io.h"

namespace sd {

Eigen::Vector3d RigFrontFromCameraBox(const Box3& box_camera) {
  // The photo's horizontal frame at the object: `toward` is the ray to the box centre with its vertical
  // (camera y, down) part removed, `right` = down × toward. Rig: toward -> -x, right -> +y.
  Eigen::Vector3d toward = box_camera.center();
  toward.y() = 0;
  if (toward.norm() < 1e-9) toward = Eigen::Vector3d::UnitZ();
  toward.normalize();
  const Eigen::Vector3d right = Eigen::Vector3d::UnitY().cross(toward);
  const Eigen::Vector3d heading = box_camera.T_frame_box.rotation * Eigen::Vector3d::UnitX();
  Eigen::Vector3d front(-heading.dot(toward), heading.dot(right), 0);
  if (front.norm() < 1e-9) return Eigen::Vector3d::UnitX();  // box pointing straight up or down: no facing
  return front.normalized();
}

MinedObject LoadMinedObject(const mining::ManifestEntry& entry) {
  const mining::MinedItem& item = entry.item;
  MinedObject o;
  o.image = ReadImage(item.crop_file, 3);
  const double s = item.crop_scale;
  // box2d is in source-image pixels; the crop is the window crop_rect scaled by crop_scale.
  o.box = Box2{(item.box2d.x1 - item.crop_rect.x1) * s, (item.box2d.y1 - item.crop_rect.y1) * s,
               (item.box2d.x2 - item.crop_rect.x1) * s, (item.box2d.y2 - item.crop_rect.y1) * s};
  o.box.x1 = std::clamp(o.box.x1, 0.0, double(o.image.width()));
  o.box.x2 = std::clamp(o.box.x2, 0.0, double(o.image.width()));
  o.box.y1 = std::clamp(o.box.y1, 0.0, double(o.image.height()));
  o.box.y2 = std::clamp(o.box.y2, 0.0, double(o.image.height()));
  if (!item.mask_file.empty()) {
    SegmentationPrior prior;
    prior.mask = ReadImage(item.mask_file, 1);
    prior.source = item.mask_source.empty() ? "box" : item.mask_source;
    if (prior.mask.width() != o.image.width() || prior.mask.height() != o.image.height())
      throw InputError(item.mask_file, Msg() << "mask is " << prior.mask.width() << "x" << prior.mask.height()
                                             << ", its crop " << o.image.width() << "x" << o.image.height());
    o.prior = std::move(prior);
  }
  o.category = item.category;
  if (item.box_ego) o.size_lwh = item.box_ego->size;
  if (item.box_camera) o.front_in_rig = RigFrontFromCameraBox(*item.box_camera);
  o.source = item.kind == mining::SourceKind::kLog
                 ? item.source + " frame " + item.frame_token + " " + item.camera + " annotation " + item.annotation_token
                 : item.origin;
  return o;
}

}  // namespace sd
