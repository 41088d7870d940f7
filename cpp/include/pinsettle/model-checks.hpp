//
// Copyright (c) 2026 pinsettle contributors
//

#ifndef __pinsettle_model_checks_hpp__
#define __pinsettle_model_checks_hpp__

#include <pinocchio/multibody/fwd.hpp>

namespace pinsettle
{

  ///
  /// \brief Check that the algorithms pinsettle runs on a model (pinocchio::aba, rnea, crba,
  /// computeGeneralizedGravityDerivatives, constraintDynamics, integrate) support it, so that a
  /// model they do not support is refused with a message instead of crashing the process
  /// (Pinocchio only asserts on these in its C++ algorithms; release builds run on).
  ///
  /// Refused:
  /// - a mimic joint (pinocchio::JointModelMimic, as pinocchio.buildModelFromUrdf(path,
  ///   mimic=True) makes of a URDF <mimic> tag), also inside a composite joint: it couples
  ///   q_follower = multiplier * q_leader + offset, which pinocchio::aba does not support;
  /// - a joint type this check does not know (one a later Pinocchio adds);
  /// - a model whose tables disagree with each other (joint, parent, name, placement and inertia
  ///   lists of different lengths, a parent listed after its child, joints' configuration or
  ///   velocity indices that do not tile q and v);
  /// - joints not in depth-first order (a joint's descendants not right after it, as a model
  ///   built by hand branch by branch can have them): pinocchio::crba and the derivatives assume
  ///   that order and would give a wrong mass matrix and stiffness.
  ///
  /// \throws std::invalid_argument naming the joint and why.
  ///
  void checkSupportedModel(const pinocchio::Model & model);

} // namespace pinsettle

#endif // ifndef __pinsettle_model_checks_hpp__
