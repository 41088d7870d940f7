//
// Copyright (c) 2026 pinsettle contributors
//

#include "pinsettle/result.hpp"
#include "pinsettle/setting-fields.hpp"
#include "pinsettle/settings.hpp"

#include <cmath>
#include <cstdint>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>
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
    bool finiteAtLeast0(double x)
    {
      return std::isfinite(x) && x >= 0.;
    }

    bool finiteAbove0(double x)
    {
      return std::isfinite(x) && x > 0.;
    }

    bool finiteAtLeast1(double x)
    {
      return std::isfinite(x) && x >= 1.;
    }

    // NaN fails every comparison, so it is outside every range.
    bool inUnitHalfOpen(double x)
    {
      return x >= 0. && x < 1.;
    }

    bool inUnitClosedAbove0(double x)
    {
      return x > 0. && x <= 1.;
    }

    bool atLeast0(double x)
    {
      return x >= 0.;
    }

    bool atLeast1(double x)
    {
      return x >= 1.;
    }

    bool atLeast2(double x)
    {
      return x >= 2.;
    }

    bool above0(double x) // +inf passes: no limit
    {
      return x > 0.;
    }

    bool isKnownEnergyMeasure(EnergyMeasure energy)
    {
      return energy == EnergyMeasure::Exact || energy == EnergyMeasure::Simplified;
    }

    // Whether s's field passes its rule.
    bool passes(const SettingField & field, const Settings & s)
    {
      return std::visit(
        [&](auto member) -> bool {
          const auto value = s.*member;
          using T = std::decay_t<decltype(value)>;
          if constexpr (std::is_same_v<T, EnergyMeasure>)
            return isKnownEnergyMeasure(value);
          else if constexpr (std::is_same_v<T, bool>)
            return true;
          else if constexpr (std::is_same_v<T, Toggle>)
            return value == Toggle::Off || value == Toggle::On || value == Toggle::Auto;
          else
          {
            const double x = static_cast<double>(value);
            if (field.kind == SettingKind::AutoNumber && x == 0.)
              return true;
            return field.accepts == nullptr || field.accepts(x);
          }
        },
        field.member);
    }

    // s's field as a message prints it (an integer without a decimal point). Made only for a
    // field that fails: a stream per field made every solve's check take 4 us.
    std::string givenValue(const SettingField & field, const Settings & s)
    {
      std::ostringstream given;
      given.precision(17);
      std::visit(
        [&](auto member) {
          const auto value = s.*member;
          using T = std::decay_t<decltype(value)>;
          if constexpr (std::is_same_v<T, EnergyMeasure> || std::is_same_v<T, Toggle>)
            given << static_cast<int>(value);
          else
            given << value;
        },
        field.member);
      return given.str();
    }
  } // namespace

  const std::vector<SettingField> & settingFields()
  {
    using K = SettingKind;
    static const std::vector<SettingField> fields = {
      {"dt", K::AutoNumber, &Settings::dt, "a finite number > 0 (seconds)",
       "Time step (s), or 'auto' (the default): dt_safety times the stability limit 2 / "
       "omega_max, re-estimated as the mechanism moves.",
       finiteAbove0, true},
      {"dt_safety", K::AutoNumber, &Settings::dt_safety, "a number in (0, 1]",
       "Fraction of the stability limit dt='auto' uses, or 'auto' (the default): 0.3 with "
       "backtrack and the exact energy, 0.2 otherwise (measured).",
       inUnitClosedAbove0, true},
      {"dt_growth", K::AutoNumber, &Settings::dt_growth, "a finite number >= 1",
       "Largest factor dt='auto' grows by between damping events (1: fixed), or 'auto' (the "
       "default): 2.5 with backtrack, the exact energy and scale_stiff_modes, 1 otherwise "
       "(measured).",
       finiteAtLeast1, true},
      {"kt", K::Number, &Settings::kt, "in [0, 1)",
       "Velocity scale at each energy peak (0, the default: stopped dead).", inUnitHalfOpen, true},
      {"err", K::Number, &Settings::err, "a finite number >= 0",
       "Relative peak threshold of the energy signal.", finiteAtLeast0, true},
      {"ds", K::Integer, &Settings::ds, "an integer >= 1 (steps)",
       "Length of the stopping window (steps).", atLeast1, true},
      {"max_e", K::Number, &Settings::max_e, "a finite number >= 0",
       "Bound on the sum of the last ds energy samples (J for the exact measure).", finiteAtLeast0,
       true},
      {"max_steps", K::Integer, &Settings::max_steps, "an integer >= 1", "Largest number of steps.",
       atLeast1, true},
      {"max_time", K::Number, &Settings::max_time, "a number > 0 (seconds; inf for no limit)",
       "Wall-clock budget (s); inf: none.", above0, true},
      {"energy", K::Choice, &Settings::energy, "\"exact\" or \"simplified\"",
       "Energy signal of the peak detector and the stopping rule.", nullptr, true},
      {"backtrack", K::Switch, &Settings::backtrack, "true or false",
       "Back up to the interpolated peak before damping.", nullptr, true},
      {"polish", K::Switch, &Settings::polish, "true or false", "Newton polish after convergence.",
       nullptr, true},
      {"newton_takeover", K::Switch, &Settings::newton_takeover, "true or false",
       "With the polish: Newton tried at damping events; a rest it reaches at round-off ends "
       "the run.",
       nullptr, true},
      {"scale_stiff_modes", K::Switch, &Settings::scale_stiff_modes, "true or false",
       "With dt='auto': slow down modes far stiffer than the rest (equilibria unchanged).", nullptr,
       true},
      {"scale_joint_inertia", K::AutoSwitch, &Settings::scale_joint_inertia,
       "true, false or 'auto'",
       "With dt='auto', on a tree: a fictitious inertia per joint that brings every joint's "
       "rate down towards the slowest one's (equilibria unchanged); 'auto' (the default): on "
       "mechanisms of 20 degrees of freedom or more without ground contacts (measured).",
       nullptr, true},
      {"trace_every", K::Integer, &Settings::trace_every, "an integer >= 0 (0 disables the trace)",
       "Record a trace sample every N steps; 0: no trace.", atLeast0, false},
      {"trace_capacity", K::Integer, &Settings::trace_capacity, "an integer >= 2",
       "Most trace samples kept (when full, every other one is dropped).", atLeast2, false},
      {"trace_configurations", K::Switch, &Settings::trace_configurations, "true or false",
       "Record q in each trace sample (for playback).", nullptr, false},
      {"check_every", K::Integer, &Settings::check_every, "an integer >= 1 (steps)",
       "Steps between checks of the clock, the callback and Ctrl-C.", atLeast1, false},
    };
    return fields;
  }

  void checkSettings(const Settings & s)
  {
    for (const SettingField & field : settingFields())
    {
      if (passes(field, s))
        continue;
      std::ostringstream msg;
      msg << field.name << " must be " << field.expected
          << (field.kind == SettingKind::AutoNumber ? ", or 0 for 'auto'" : "") << ", got "
          << givenValue(field, s);
      throw std::invalid_argument(msg.str());
    }
  }

} // namespace pinsettle
