// Shared by the two-level scene and its transforms (transforms.cpp).
#pragma once
#include "kestrel/instances.h"

namespace kestrel {

/// The inverse of a transform already known to be invertible (transform_problem() == "").
Affine3 inverse_of_valid(const Affine3& a);

}  // namespace kestrel
