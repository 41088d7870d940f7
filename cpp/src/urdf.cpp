//
// Copyright (c) 2026 pinsettle contributors
//

#include "pinsettle/urdf.hpp"

#include <pinocchio/parsers/urdf.hpp>

#include <fstream>
#include <stdexcept>

namespace pinsettle
{

  pinocchio::Model buildModelFromUrdf(const std::string & path, bool floating)
  {
    if (!std::ifstream(path).good())
      throw std::invalid_argument("URDF file not found or not readable: '" + path + "'");
    pinocchio::Model model;
    try
    {
      if (floating)
        pinocchio::urdf::buildModel(path, pinocchio::JointModelFreeFlyer(), model);
      else
        pinocchio::urdf::buildModel(path, model);
    }
    catch (const std::exception & e)
    {
      throw std::invalid_argument("URDF file '" + path + "' does not parse: " + e.what());
    }
    return model;
  }

} // namespace pinsettle
