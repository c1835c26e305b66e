#include "geometry/normals.h"
