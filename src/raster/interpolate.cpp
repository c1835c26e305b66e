#include "raster/raster.h"
