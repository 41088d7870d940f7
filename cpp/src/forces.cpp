//
// Copyright (c) 2026 pinsettle contributors
//

#include "pinsettle/forces.hpp"

namespace pinsettle
{

  ConstantGeneralizedForce::ConstantGeneralizedForce(const Eigen::VectorXd & tau)
  : tau_(tau)
  {
  }

  void ConstantGeneralizedForce::computeForces(
    const pinocchio::Model & model,
    pinocchio::Data & /*data*/,
    const Eigen::VectorXd & /*q*/,
    const Eigen::VectorXd & /*v*/,
    Eigen::VectorXd & tau,
    ForceVector & /*fext*/) const
  {
    if (tau_.size() != model.nv)
      throw std::invalid_argument(
        "ConstantGeneralizedForce: effort has " + std::to_string(tau_.size())
        + " entries, the model has nv = " + std::to_string(model.nv));
    tau += tau_;
  }

  double ConstantGeneralizedForce::computeWork(
    const pinocchio::Model & model,
    pinocchio::Data & /*data*/,
    const Eigen::VectorXd & /*q_from*/,
    const Eigen::VectorXd & /*q_to*/,
    const Eigen::VectorXd & motion) const
  {
    if (tau_.size() != model.nv || motion.size() != model.nv)
      return std::numeric_limits<double>::quiet_NaN();
    return tau_.dot(motion);
  }

  bool ConstantGeneralizedForce::tiesToWorld(
    const pinocchio::Model & model, pinocchio::JointIndex root) const
  {
    return tau_.size() != model.nv || !tau_.segment(model.idx_vs[root], model.nvs[root]).isZero(0.);
  }

} // namespace pinsettle
