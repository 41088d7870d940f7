//
// Copyright (c) 2026 pinsettle contributors
//

#ifndef __pinsettle_model_checks_hpp__
#define __pinsettle_model_checks_hpp__

#include <pinocchio/multibody/fwd.hpp>

#include <vector>

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
  ///   q_follower = multiplier * q_leader + offset, which pinocchio::aba does not support
  ///   (releaseMimicJoints turns such a model into one the solver takes, with the couplings as
  ///   LoopConstraints::addCoupling constraints; pinsettle's Python layer does so itself);
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

  /// \brief A mimic joint of a model: q[follower] = multiplier * q[leader] + offset.
  struct MimicJoint
  {
    pinocchio::JointIndex follower; ///< Index in the model (and in the released model).
    pinocchio::JointIndex leader;
    double multiplier;
    double offset;
  };

  ///
  /// \brief The model with each mimic joint made an ordinary joint of its own type and axis
  /// (what pinocchio.buildModelFromUrdf(path, mimic=False) makes of the URDF), the same joint
  /// indices, names, placements, inertias and frames; a follower has no position limits (the
  /// mimic model keeps none for it) and the effort, velocity, friction, damping and armature
  /// defaults. Couple the followers back with LoopConstraints::addCoupling.
  ///
  /// \param[out] mimics The mimic joints found, in joint order (empty: the copy is the model).
  /// \throws std::invalid_argument naming the joint for a mimic joint with other than one
  ///         configuration entry and one velocity, one inside a composite joint, or one that
  ///         follows a joint after it or another mimic joint.
  ///
  pinocchio::Model releaseMimicJoints(
    const pinocchio::Model & model, std::vector<MimicJoint> & mimics);

} // namespace pinsettle

#endif // ifndef __pinsettle_model_checks_hpp__
