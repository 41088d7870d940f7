//
// Copyright (c) 2026 pinsettle contributors
//

#ifndef __pinsettle_energy_hpp__
#define __pinsettle_energy_hpp__

#include <pinocchio/multibody.hpp>

namespace pinsettle
{

  ///
  /// \brief Exact kinetic energy sum_i 1/2 m_i |v_i|^2 + 1/2 w_i^T I_i w_i from the body
  /// velocities of a previous forward pass (pinocchio::aba or pinocchio::forwardKinematics with
  /// a velocity), without forming the mass matrix.
  ///
  /// \param[in] model The model of the mechanism.
  /// \param[in] data Data of that pass: in the local convention data.v holds the joint spatial
  /// velocities in local frames; in the world convention (pinocchio::aba with
  /// pinocchio::Convention::WORLD) data.ov holds them in the world frame and data.oh the bodies'
  /// momenta there (data.oinertias times data.ov).
  /// \param[in] convention The convention of that pass.
  /// \return The kinetic energy (J); equals 1/2 v^T M(q) v.
  ///
  double computeBodyKineticEnergy(
    const pinocchio::Model & model,
    const pinocchio::Data & data,
    pinocchio::Convention convention = pinocchio::Convention::LOCAL);

  ///
  /// \brief Simplified energy sum_i |v_com,i|^2 + |w_i|^2 over the bodies (masses and inertias
  /// dropped) from the body velocities of a previous forward pass, as above. A body is the
  /// inertia that Pinocchio attaches to a joint; bodies with neither mass nor rotational inertia
  /// are skipped.
  ///
  /// \return The simplified energy (m^2/s^2 + rad^2/s^2).
  ///
  double computeSimplifiedKineticEnergy(
    const pinocchio::Model & model,
    const pinocchio::Data & data,
    pinocchio::Convention convention = pinocchio::Convention::LOCAL);

  ///
  /// \brief Both energy measures at the state (q, v): runs pinocchio::forwardKinematics and the
  /// two functions above. A convenience for tests and tools; the solver reuses the body velocities
  /// ABA already produced instead.
  ///
  /// \param[in] q The joint configuration (dim model.nq).
  /// \param[in] v The joint velocity (dim model.nv).
  /// \return (exact energy in J, simplified energy).
  ///
  std::pair<double, double> computeKineticEnergies(
    const pinocchio::Model & model,
    pinocchio::Data & data,
    const Eigen::VectorXd & q,
    const Eigen::VectorXd & v);

  ///
  /// \brief The potential energy of gravity at q, -sum_i m_i g . c_i (J, with model.gravity;
  /// zero at the world origin): runs pinocchio::forwardKinematics.
  ///
  /// \param[in] q The joint configuration (dim model.nq).
  ///
  double computeGravityPotentialEnergy(
    const pinocchio::Model & model, pinocchio::Data & data, const Eigen::VectorXd & q);

} // namespace pinsettle

#endif // ifndef __pinsettle_energy_hpp__
