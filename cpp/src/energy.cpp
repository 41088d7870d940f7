//
// Copyright (c) 2026 pinsettle contributors
//

#include "pinsettle/energy.hpp"

#include <pinocchio/algorithm/kinematics.hpp>

namespace pinsettle
{

  double computeBodyKineticEnergy(const pinocchio::Model & model, const pinocchio::Data & data)
  {
    double energy = 0.;
    for (pinocchio::JointIndex i = 1; i < static_cast<pinocchio::JointIndex>(model.njoints); ++i)
      energy += model.inertias[i].vtiv(data.v[i]);
    return 0.5 * energy;
  }

  double computeSimplifiedKineticEnergy(
    const pinocchio::Model & model, const pinocchio::Data & data)
  {
    double energy = 0.;
    for (pinocchio::JointIndex i = 1; i < static_cast<pinocchio::JointIndex>(model.njoints); ++i)
    {
      const pinocchio::Inertia & body = model.inertias[i];
      if (body.mass() <= 0. && body.inertia().data().isZero(0.))
        continue; // a massless frame, not a body
      const pinocchio::Motion & vi = data.v[i];
      // Velocity of the centre of mass: v_O + w x c, c the lever in the joint frame.
      const Eigen::Vector3d v_com = vi.linear() + vi.angular().cross(body.lever());
      energy += v_com.squaredNorm() + vi.angular().squaredNorm();
    }
    return energy;
  }

  std::pair<double, double> computeKineticEnergies(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const Eigen::VectorXd & v)
  {
    pinocchio::forwardKinematics(model, data, q, v);
    return {computeBodyKineticEnergy(model, data), computeSimplifiedKineticEnergy(model, data)};
  }

} // namespace pinsettle
