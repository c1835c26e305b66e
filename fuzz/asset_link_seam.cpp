// The asset target compiles assetgen/asset.cpp alone (the assetgen library links the renderer, Embree, LibTorch
// and FAISS). asset.cpp's writer calls these two; LoadAsset, the parser under test, never does. They stop the
// program if that ever changes, rather than pretending to write a preview or views.
#include "assetgen/preview.h"
#include "assetgen/views.h"
#include "core/error.h"

namespace sd {

ImageU8 RenderPreview(const TriangleMesh&, int, int) {
  CheckFailed(__FILE__, __LINE__, "false", "RenderPreview is not linked into the fuzz targets");
}

void SaveViews(const MultiViewSet&, const std::filesystem::path&, const std::string&, bool) {
  CheckFailed(__FILE__, __LINE__, "false", "SaveViews is not linked into the fuzz targets");
}

}  // namespace sd
