//
// Copyright (c) 2026 pinsettle contributors
//

#ifndef __pinsettle_pinsettle_hpp__
#define __pinsettle_pinsettle_hpp__

#include "pinsettle/constraint-set.hpp"
#include "pinsettle/contacts.hpp"
#include "pinsettle/damping.hpp"
#include "pinsettle/elements.hpp"
#include "pinsettle/energy.hpp"
#include "pinsettle/forces.hpp"
#include "pinsettle/loops.hpp"
#include "pinsettle/model-checks.hpp"
#include "pinsettle/monitors.hpp"
#include "pinsettle/prebuilt.hpp"
#include "pinsettle/result.hpp"
#include "pinsettle/setting-fields.hpp"
#include "pinsettle/settings.hpp"
#include "pinsettle/solver.hpp"
#include "pinsettle/stability.hpp"
#include "pinsettle/statics.hpp"
#include "pinsettle/step-control.hpp"
#include "pinsettle/stops.hpp"
#include "pinsettle/urdf.hpp"

#endif // ifndef __pinsettle_pinsettle_hpp__
