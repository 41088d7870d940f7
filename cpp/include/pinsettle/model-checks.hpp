//
// Copyright (c) 2026 pinsettle contributors
//

#ifndef __pinsettle_model_checks_hpp__
#define __pinsettle_model_checks_hpp__

#include <pinocchio/multibody/fwd.hpp>

#include <cstddef>
#include <stdexcept>
#include <string>
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
  /// - a body whose inertia no rigid body has: a negative or non-finite mass, a non-finite centre
  ///   of mass or rotational inertia, a rotational inertia that is not positive semidefinite
  ///   (the message names the body's frames and its joint).
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

  ///
  /// \brief Memory (bytes) one pinocchio::Data of the model takes. Pinocchio 4.1 keeps four
  /// nv x nv x nv tensors of the RNEA's second-order derivatives in every Data and zeroes them
  /// when it builds one: 32 nv^3 bytes, 2 GB at nv = 400; the rest (its nv x nv matrices and
  /// per-joint blocks) is counted from above. A Solver holds one Data (two with a progress
  /// callback).
  ///
  std::size_t computeDataMemory(const pinocchio::Model & model);

  ///
  /// \brief Memory this machine has available for a new allocation (bytes): MemAvailable of
  /// /proc/meminfo where it can be read, else the physical memory; 0 when neither is known.
  ///
  std::size_t availableMemory();

  ///
  /// \brief Whether `count` pinocchio::Data of the model fit in the memory available
  /// (availableMemory; always where they take at most 256 MB, without reading it).
  ///
  bool fitsInMemory(const pinocchio::Model & model, int count);

  /// \brief A model too large for the memory of the machine (the Python module raises it as
  /// MemoryError).
  class MemoryLimitError : public std::runtime_error
  {
  public:
    using std::runtime_error::runtime_error;
  };

  ///
  /// \brief Check that `count` pinocchio::Data of the model fit in the memory available, before
  /// one is built (building one that does not fit ends the process: the kernel's out-of-memory
  /// killer, not an exception).
  ///
  /// \param[in] what What the Data is for, named in the message ("the solver").
  /// \throws MemoryLimitError saying how much the model needs (nv, GB) and how much is available.
  ///
  void checkDataMemory(const pinocchio::Model & model, int count, const char * what);

  /// \brief A pinocchio::Data of the model, checked first (checkDataMemory).
  pinocchio::Data makeData(const pinocchio::Model & model, const char * what);

} // namespace pinsettle

#endif // ifndef __pinsettle_model_checks_hpp__
