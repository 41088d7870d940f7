//
// Copyright (c) 2026 pinsettle contributors
//

#ifndef __pinsettle_statics_hpp__
#define __pinsettle_statics_hpp__

#include "pinsettle/forces.hpp"

namespace pinsettle
{

  ///
  /// \brief Net static generalized force: rnea(q, 0, 0) minus the applied efforts at (q, 0),
  /// i.e. gravity minus springs and loads. Zero at an equilibrium.
  ///
  /// \param[in] q The joint configuration (dim model.nq).
  /// \param[in] forces Applied efforts, or nullptr for gravity alone.
  /// \return The net static generalized force (dim model.nv, N m or N).
  ///
  Eigen::VectorXd computeStaticForce(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const ForceModel * forces = nullptr);

  ///
  /// \brief Static residual: max |rnea(q, 0, 0) - applied generalized forces at (q, 0)|.
  ///
  /// \param[in] q The joint configuration (dim model.nq).
  /// \param[in] forces Applied efforts, or nullptr for gravity alone.
  /// \return The largest absolute net static generalized force (N m or N).
  ///
  double computeStaticResidual(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const ForceModel * forces = nullptr);

} // namespace pinsettle

#endif // ifndef __pinsettle_statics_hpp__
