//
// Copyright (c) 2026 pinsettle contributors
//
// Private to the library: which configuration entries of a joint have unit norm.
//

#ifndef __pinsettle_unit_norm_hpp__
#define __pinsettle_unit_norm_hpp__

#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/multibody/model.hpp>

namespace pinsettle
{

  ///
  /// \brief Which configuration entries of a joint lie on a unit-norm group (a quaternion, a
  /// continuous joint's cos and sin): those pinocchio::normalize changes in a segment of ones.
  ///
  /// \param[in] neutral pinocchio::neutral(model) (dim model.nq): the other joints' entries,
  /// which normalize leaves alone.
  /// \return One flag per entry of the joint (dim model.nqs[joint]).
  ///
  inline Eigen::Array<bool, Eigen::Dynamic, 1> unitNormEntries(
    const pinocchio::Model & model, pinocchio::JointIndex joint, const Eigen::VectorXd & neutral)
  {
    const int iq = model.idx_qs[joint], nq = model.nqs[joint];
    Eigen::VectorXd probe = neutral;
    probe.segment(iq, nq).setOnes();
    pinocchio::normalize(model, probe);
    return probe.segment(iq, nq).array() != 1.;
  }

} // namespace pinsettle

#endif // ifndef __pinsettle_unit_norm_hpp__
