//
// Copyright (c) 2026 pinsettle contributors
//

#include "pinsettle/result.hpp"
#include "pinsettle/settings.hpp"

#include <cmath>
#include <cstdint>
#include <sstream>
#include <stdexcept>
#include <variant>

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
    // One field's rule: its name, what it must be (the message's words), whether it is, and the
    // value given (printed as given: an integer field without a decimal point).
    struct FieldRule
    {
      const char * name;
      const char * expected;
      bool valid;
      std::variant<double, std::int64_t> given;
    };

    bool finiteAtLeast(double value, double low)
    {
      return std::isfinite(value) && value >= low;
    }

    // NaN fails every comparison, so it is outside every range.
    bool inClosedRange(double value, double low, double high)
    {
      return value >= low && value <= high;
    }

    bool inHalfOpenRange(double value, double low, double high)
    {
      return value >= low && value < high;
    }

    // 0 asks for the measured default.
    bool zeroOrFiniteAtLeast(double value, double low)
    {
      return value == 0. || finiteAtLeast(value, low);
    }

    bool isKnownEnergyMeasure(EnergyMeasure energy)
    {
      return energy == EnergyMeasure::Exact || energy == EnergyMeasure::Simplified;
    }

    [[noreturn]] void fail(const FieldRule & rule)
    {
      std::ostringstream msg;
      msg.precision(17);
      msg << rule.name << " must be " << rule.expected << ", got ";
      std::visit([&msg](auto value) { msg << value; }, rule.given);
      throw std::invalid_argument(msg.str());
    }
  } // namespace

  void checkSettings(const Settings & s)
  {
    // In this order: the first field that breaks its rule is the one reported.
    const FieldRule rules[] = {
      {"dt", "a finite number > 0 (seconds), or 0 for the automatic step", finiteAtLeast(s.dt, 0.),
       s.dt},
      {"dt_safety", "in (0, 1], or 0 for the measured default", inClosedRange(s.dt_safety, 0., 1.),
       s.dt_safety},
      {"dt_growth", "a finite number >= 1, or 0 for the measured default",
       zeroOrFiniteAtLeast(s.dt_growth, 1.), s.dt_growth},
      {"kt", "in [0, 1)", inHalfOpenRange(s.kt, 0., 1.), s.kt},
      {"err", "a finite number >= 0", finiteAtLeast(s.err, 0.), s.err},
      {"ds", "an integer >= 1 (steps)", s.ds >= 1, s.ds},
      {"max_e", "a finite number >= 0", finiteAtLeast(s.max_e, 0.), s.max_e},
      {"max_steps", "an integer >= 1", s.max_steps >= 1, s.max_steps},
      // NaN fails too; +inf means no limit
      {"max_time", "a number > 0 (seconds; inf for no limit)", s.max_time > 0., s.max_time},
      {"trace_every", "an integer >= 0 (0 disables the trace)", s.trace_every >= 0, s.trace_every},
      {"trace_capacity", "an integer >= 2", s.trace_capacity >= 2, s.trace_capacity},
      {"check_every", "an integer >= 1 (steps)", s.check_every >= 1, s.check_every},
      {"energy", "\"exact\" or \"simplified\"", isKnownEnergyMeasure(s.energy),
       std::int64_t{static_cast<int>(s.energy)}},
    };
    for (const FieldRule & rule : rules)
      if (!rule.valid)
        fail(rule);
  }

} // namespace pinsettle
