#include "geometry/visual_hull.h"
