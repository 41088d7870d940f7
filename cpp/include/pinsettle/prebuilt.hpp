//
// Copyright (c) 2026 pinsettle contributors
//
// Pinocchio's aba and crba through the explicit instantiations that pinocchio_default carries.
//

#ifndef __pinsettle_prebuilt_hpp__
#define __pinsettle_prebuilt_hpp__

#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/multibody/data.hpp>
#include <pinocchio/multibody/model.hpp>

#include <vector>

namespace pinsettle
{

  ///
  /// \brief Pinocchio's aba and crba called with the argument types of the explicit
  /// instantiations in the pinocchio_default library (Eigen::Ref<const Eigen::VectorXd>), so that
  /// no translation unit compiles them again. Called with an Eigen::VectorXd, pinocchio::crba and
  /// pinocchio::aba are instantiated anew in each file that calls them (measured with
  /// -fsyntax-only on a 2-core machine: 40 s for crba and 50 s for aba, per file); the other
  /// algorithms the core calls (rnea, computeGeneralizedGravity, forwardKinematics, ...) already
  /// go through such references inside Pinocchio.
  ///
  namespace prebuilt
  {
    typedef Eigen::Ref<const Eigen::VectorXd> ConstVectorRef;

    ///
    /// \brief pinocchio::aba: the joint acceleration (dim model.nv, rad/s^2 or m/s^2), also in
    /// data.ddq.
    ///
    /// \param[in] q Joint configuration (dim model.nq).
    /// \param[in] v Joint velocity (dim model.nv).
    /// \param[in] tau Joint effort (dim model.nv, N m or N).
    ///
    inline const Eigen::VectorXd & aba(
      const pinocchio::Model & model,
      pinocchio::Data & data,
      const ConstVectorRef & q,
      const ConstVectorRef & v,
      const ConstVectorRef & tau,
      const pinocchio::Convention convention = pinocchio::Convention::LOCAL)
    {
      return pinocchio::aba(model, data, q, v, tau, convention);
    }

    ///
    /// \brief pinocchio::aba with external forces: fext holds one spatial force per joint
    /// (model.njoints), in the joint's local frame.
    ///
    inline const Eigen::VectorXd & aba(
      const pinocchio::Model & model,
      pinocchio::Data & data,
      const ConstVectorRef & q,
      const ConstVectorRef & v,
      const ConstVectorRef & tau,
      const std::vector<pinocchio::Force> & fext,
      const pinocchio::Convention convention = pinocchio::Convention::LOCAL)
    {
      return pinocchio::aba(model, data, q, v, tau, fext, convention);
    }

    ///
    /// \brief pinocchio::crba: the joint-space mass matrix (model.nv x model.nv, upper triangle
    /// filled), in data.M.
    ///
    /// \param[in] q Joint configuration (dim model.nq).
    ///
    inline const Eigen::MatrixXd & crba(
      const pinocchio::Model & model,
      pinocchio::Data & data,
      const ConstVectorRef & q,
      const pinocchio::Convention convention = pinocchio::Convention::LOCAL)
    {
      return pinocchio::crba(model, data, q, convention);
    }
  } // namespace prebuilt

} // namespace pinsettle

#endif // ifndef __pinsettle_prebuilt_hpp__
