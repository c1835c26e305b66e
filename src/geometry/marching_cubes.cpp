#include "geometry/marching_cubes.h"
