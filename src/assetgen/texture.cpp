#include "assetgen/texture.h"
