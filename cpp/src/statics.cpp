//
// Copyright (c) 2026 pinsettle contributors
//

#include "pinsettle/statics.hpp"

#include <pinocchio/algorithm/rnea.hpp>

namespace pinsettle
{

  Eigen::VectorXd computeStaticForce(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const ForceModel * forces)
  {
    if (!forces || forces->empty())
      return pinocchio::computeGeneralizedGravity(model, data, q);
    const Eigen::VectorXd zero = Eigen::VectorXd::Zero(model.nv);
    Eigen::VectorXd tau = Eigen::VectorXd::Zero(model.nv);
    ForceVector fext(model.joints.size(), pinocchio::Force::Zero());
    forces->computeForces(model, data, q, zero, tau, fext);
    if (forces->hasExternalForces())
      return pinocchio::rnea(model, data, q, zero, zero, fext) - tau;
    return pinocchio::computeGeneralizedGravity(model, data, q) - tau;
  }

  double computeStaticResidual(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const ForceModel * forces)
  {
    return computeStaticForce(model, data, q, forces).lpNorm<Eigen::Infinity>();
  }

} // namespace pinsettle
