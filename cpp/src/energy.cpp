//
// Copyright (c) 2026 pinsettle contributors
//

#include "pinsettle/energy.hpp"

#include <pinocchio/algorithm/kinematics.hpp>

namespace pinsettle
{

  double computeBodyKineticEnergy(
    const pinocchio::Model & model, const pinocchio::Data & data, pinocchio::Convention convention)
  {
    double energy = 0.;
    if (convention == pinocchio::Convention::WORLD)
    {
      // The world-convention pass leaves each body's momentum I_i v_i in data.oh: one dot
      // product a body, where forming I_i v_i again costs several times that.
      for (pinocchio::JointIndex i = 1; i < static_cast<pinocchio::JointIndex>(model.njoints); ++i)
        energy += data.ov[i].toVector().dot(data.oh[i].toVector());
    }
    else
      for (pinocchio::JointIndex i = 1; i < static_cast<pinocchio::JointIndex>(model.njoints); ++i)
        energy += model.inertias[i].vtiv(data.v[i]);
    return 0.5 * energy;
  }

  double computeSimplifiedKineticEnergy(
    const pinocchio::Model & model, const pinocchio::Data & data, pinocchio::Convention convention)
  {
    const bool world = convention == pinocchio::Convention::WORLD;
    double energy = 0.;
    for (pinocchio::JointIndex i = 1; i < static_cast<pinocchio::JointIndex>(model.njoints); ++i)
    {
      const pinocchio::Inertia & body = model.inertias[i];
      if (body.mass() <= 0. && body.inertia().data().isZero(0.))
        continue; // a massless frame, not a body
      // The velocity and the centre of mass c in one frame (the joint's, or the world's).
      const pinocchio::Motion & vi = world ? data.ov[i] : data.v[i];
      const Eigen::Vector3d & c = world ? data.oinertias[i].lever() : body.lever();
      const Eigen::Vector3d v_com = vi.linear() + vi.angular().cross(c); // v_O + w x c
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

  double computeGravityPotentialEnergy(
    const pinocchio::Model & model, pinocchio::Data & data, const Eigen::VectorXd & q)
  {
    pinocchio::forwardKinematics(model, data, q);
    const Eigen::Vector3d g = model.gravity.linear();
    double energy = 0.;
    for (pinocchio::JointIndex i = 1; i < static_cast<pinocchio::JointIndex>(model.njoints); ++i)
      energy -= model.inertias[i].mass() * g.dot(data.oMi[i].act(model.inertias[i].lever()));
    return energy;
  }

} // namespace pinsettle
