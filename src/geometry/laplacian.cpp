#include "geometry/laplacian.h"
