//
// Copyright (c) 2026 pinsettle contributors
//

#include "pinsettle/result.hpp"
#include "pinsettle/settings.hpp"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace pinsettle
{

  const char * toString(EnergyMeasure measure)
  {
    return measure == EnergyMeasure::Exact ? "exact" : "simplified";
  }

  EnergyMeasure energyMeasureFromString(const std::string & name)
  {
    if (name == "exact")
      return EnergyMeasure::Exact;
    if (name == "simplified")
      return EnergyMeasure::Simplified;
    throw std::invalid_argument("energy must be \"exact\" or \"simplified\", got \"" + name + "\"");
  }

  const char * toString(Status status)
  {
    switch (status)
    {
    case Status::Converged:
      return "converged";
    case Status::MaxSteps:
      return "max_steps";
    case Status::TimeLimit:
      return "time_limit";
    case Status::Aborted:
      return "aborted";
    case Status::Diverged:
      return "diverged";
    case Status::NoEquilibrium:
      return "no_equilibrium";
    }
    return "unknown";
  }

  const char * toString(EventKind kind)
  {
    switch (kind)
    {
    case EventKind::Damping:
      return "damping";
    case EventKind::Push:
      return "push";
    case EventKind::Rollback:
      return "rollback";
    case EventKind::Impact:
      return "impact";
    }
    return "unknown";
  }

  namespace
  {
    template<typename T>
    [[noreturn]] void fail(const char * name, const char * expected, T value)
    {
      std::ostringstream msg;
      msg.precision(17);
      msg << name << " must be " << expected << ", got " << value;
      throw std::invalid_argument(msg.str());
    }
  } // namespace

  void checkSettings(const Settings & s)
  {
    if (!(std::isfinite(s.dt) && s.dt >= 0.))
      fail("dt", "a finite number > 0 (seconds), or 0 for the automatic step", s.dt);
    if (!(s.dt_safety >= 0. && s.dt_safety <= 1.))
      fail("dt_safety", "in (0, 1], or 0 for the measured default", s.dt_safety);
    if (!(s.dt_growth == 0. || (std::isfinite(s.dt_growth) && s.dt_growth >= 1.)))
      fail("dt_growth", "a finite number >= 1, or 0 for the measured default", s.dt_growth);
    if (!(s.kt >= 0. && s.kt < 1.))
      fail("kt", "in [0, 1)", s.kt);
    if (!(std::isfinite(s.err) && s.err >= 0.))
      fail("err", "a finite number >= 0", s.err);
    if (s.ds < 1)
      fail("ds", "an integer >= 1 (steps)", s.ds);
    if (!(std::isfinite(s.max_e) && s.max_e >= 0.))
      fail("max_e", "a finite number >= 0", s.max_e);
    if (s.max_steps < 1)
      fail("max_steps", "an integer >= 1", s.max_steps);
    if (!(s.max_time > 0.)) // NaN fails too; +inf means no limit
      fail("max_time", "a number > 0 (seconds; inf for no limit)", s.max_time);
    if (s.trace_every < 0)
      fail("trace_every", "an integer >= 0 (0 disables the trace)", s.trace_every);
    if (s.trace_capacity < 2)
      fail("trace_capacity", "an integer >= 2", s.trace_capacity);
    if (s.check_every < 1)
      fail("check_every", "an integer >= 1 (steps)", s.check_every);
    if (s.energy != EnergyMeasure::Exact && s.energy != EnergyMeasure::Simplified)
      fail("energy", "\"exact\" or \"simplified\"", static_cast<int>(s.energy));
  }

} // namespace pinsettle
