#include "geometry/topology.h"
