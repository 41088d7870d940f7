//
// Copyright (c) 2026 pinsettle contributors
//
// Private to the library: which joints' motion subspaces turn with their own configuration,
// subtrees, and the joint that owns a coordinate.
//

#ifndef __pinsettle_joint_kinds_hpp__
#define __pinsettle_joint_kinds_hpp__

#include <pinocchio/multibody/model.hpp>

#include <string>

namespace pinsettle
{

  namespace detail
  {
    struct SubspaceVaries : boost::static_visitor<bool>
    {
      template<typename JointModel>
      bool operator()(const JointModel &) const
      {
        return false;
      }
      bool operator()(const pinocchio::JointModelUniversal &) const
      {
        return true;
      }
      bool operator()(const pinocchio::JointModelSphericalZYX &) const
      {
        return true;
      }
      bool operator()(const pinocchio::JointModelEllipsoid &) const
      {
        return true;
      }
      bool operator()(const pinocchio::JointModelComposite &) const
      {
        return true;
      }
      bool operator()(const pinocchio::JointModelMimic &) const
      {
        return true;
      }
    };
  } // namespace detail

  ///
  /// \brief Whether a joint's motion subspace, in its own frame, varies with its configuration
  /// (universal, ZYX spherical, ellipsoid, composite). A mimic joint, which the model checks
  /// refuse before any solve (its coupling is held as a constraint), is counted with them: its
  /// derivatives are not relied on either.
  ///
  /// The others (revolute, prismatic, helical, continuous, spherical, planar, translation,
  /// free-flyer) move by the exponential of their tangent directions (pinocchio::integrate
  /// composes on the right), so a step along direction m of a joint turns every world column
  /// J_k at or below it by J_m x J_k. Pinocchio 4.1's gravity derivatives assume as much: where
  /// the subspace varies they drop its turning (a 2 kg universal joint's K is off by 1.2 N m/rad,
  /// a composite's parts lose their coupling).
  ///
  inline bool hasVaryingMotionSubspace(const pinocchio::JointModel & joint)
  {
    return boost::apply_visitor(detail::SubspaceVaries(), joint.toVariant());
  }

  /// \brief Whether any joint of the model has a varying motion subspace.
  inline bool hasVaryingMotionSubspace(const pinocchio::Model & model)
  {
    for (std::size_t j = 1; j < model.joints.size(); ++j)
      if (hasVaryingMotionSubspace(model.joints[j]))
        return true;
    return false;
  }

  /// \brief Whether joint is root or lies below it (the world, joint 0, lies below none).
  inline bool isInSubtree(
    const pinocchio::Model & model, pinocchio::JointIndex joint, pinocchio::JointIndex root)
  {
    for (; joint != 0; joint = model.parents[joint])
      if (joint == root)
        return true;
    return false;
  }

  /// \brief "joint 'name'" of the joint that owns tangent coordinate iv (index in model.nv), for
  /// error messages.
  inline std::string describeCoordinate(const pinocchio::Model & model, Eigen::Index iv)
  {
    for (pinocchio::JointIndex j = 1; j < static_cast<pinocchio::JointIndex>(model.njoints); ++j)
      if (iv >= model.idx_vs[j] && iv < model.idx_vs[j] + model.nvs[j])
        return "joint '" + model.names[j] + "'";
    return "coordinate " + std::to_string(iv);
  }

} // namespace pinsettle

#endif // ifndef __pinsettle_joint_kinds_hpp__
