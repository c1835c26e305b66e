#include "assetgen/uv_atlas.h"
