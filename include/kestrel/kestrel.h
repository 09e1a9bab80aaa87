// kestrel: everything public in one include.
#pragma once
#include "kestrel/bvh.h"
#include "kestrel/error.h"
#include "kestrel/instances.h"
#include "kestrel/io.h"
#include "kestrel/scene.h"
#include "kestrel/parallel.h"
#include "kestrel/trace.h"
#include "kestrel/types.h"
