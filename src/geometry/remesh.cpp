#include "geometry/remesh.h"
