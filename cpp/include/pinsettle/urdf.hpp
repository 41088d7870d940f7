//
// Copyright (c) 2026 pinsettle contributors
//

#ifndef __pinsettle_urdf_hpp__
#define __pinsettle_urdf_hpp__

#include <pinocchio/multibody.hpp>

#include <string>

namespace pinsettle
{

  ///
  /// \brief Build the kinematic and inertial model of a URDF file (no meshes are loaded).
  ///
  /// Compiled once in the library so that programs using pinsettle need not include
  /// Pinocchio's URDF parser.
  ///
  /// \param[in] path Path of the URDF file.
  /// \param[in] floating Attach the root link with a free-flyer joint.
  /// \throws std::invalid_argument when the file is missing or does not parse.
  ///
  pinocchio::Model buildModelFromUrdf(const std::string & path, bool floating = false);

} // namespace pinsettle

#endif // ifndef __pinsettle_urdf_hpp__
