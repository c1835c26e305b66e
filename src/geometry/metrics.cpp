#include "geometry/metrics.h"
