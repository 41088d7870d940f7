//
// Copyright (c) 2026 pinsettle contributors
//

#ifndef __pinsettle_setting_fields_hpp__
#define __pinsettle_setting_fields_hpp__

#include "pinsettle/settings.hpp"

#include <cstdint>
#include <variant>
#include <vector>

namespace pinsettle
{

  /// \brief How a setting is given.
  enum class SettingKind
  {
    Number,     ///< a real number
    Integer,    ///< an integer
    Switch,     ///< on or off
    AutoNumber, ///< a real number, or 'auto' (stored as 0): the measured or estimated value
    AutoSwitch, ///< on, off or 'auto' (Toggle): the measured rule
    Choice      ///< one of named values (the energy measure)
  };

  ///
  /// \brief One setting, declared once for every interface. settingFields() lists them; from
  /// that list come checkSettings, the Python binding's properties and their docs, the Python
  /// layer's types and its type stubs, and the command line's flags.
  ///
  struct SettingField
  {
    using Member = std::variant<
      double Settings::*,
      std::int64_t Settings::*,
      bool Settings::*,
      Toggle Settings::*,
      EnergyMeasure Settings::*>;

    const char * name;
    SettingKind kind;
    Member member;
    /// What a value must be, as the messages refusing one say it ("in [0, 1)"); for an
    /// AutoNumber, what a number must be ('auto' aside).
    const char * expected;
    /// What it does, in a line or two (the binding's docstring, the command line's help).
    const char * help;
    /// Whether a number is allowed (Number, Integer, AutoNumber's numbers); nullptr: any.
    bool (*accepts)(double);
    /// Whether the command line has a flag for it (the trace's and the poll's settings are
    /// for programs).
    bool command_line;
  };

  /// \brief Every setting, in the order checkSettings looks at them.
  const std::vector<SettingField> & settingFields();

} // namespace pinsettle

#endif // ifndef __pinsettle_setting_fields_hpp__
