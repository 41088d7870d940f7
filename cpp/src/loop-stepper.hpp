//
// Copyright (c) 2026 pinsettle contributors
//
// Private to the library: the per-step work of a solve with loop closures.
//

#ifndef __pinsettle_loop_stepper_hpp__
#define __pinsettle_loop_stepper_hpp__

#include "pinsettle/loops.hpp"

#include <memory>

namespace pinsettle
{

  ///
  /// \brief Constrained dynamics and the projections onto the loops, with its workspace
  /// allocated once (Pinocchio's constraint models and data live in the implementation, so
  /// that only loops.cpp compiles Pinocchio's constrained dynamics).
  ///
  class LoopStepper
  {
  public:
    LoopStepper(const pinocchio::Model & model, const LoopConstraints & loops);
    ~LoopStepper();

    /// \brief Set up for a solve from q (on the loops): sizes the constraint data and scales
    /// the proximal regularisation to the mechanism's Delassus matrix.
    void init(pinocchio::Data & data, const Eigen::VectorXd & q);

    ///
    /// \brief Constrained forward dynamics (pinocchio::constraintDynamics; with joint couplings,
    /// a = N s_dot with (N^T M N) s_dot = N^T (tau - b) from crba and rnea, N the motions they
    /// allow, and the loops' rows, if any, as constraints on s_dot):
    /// data.ddq holds the acceleration; data.v the body velocities (local frames) for the
    /// energy measures.
    ///
    /// \param[in] tau Applied joint efforts (dim model.nv).
    /// \param[in] fext Spatial forces per joint (local frames), or nullptr.
    ///
    void dynamics(
      pinocchio::Data & data,
      const Eigen::VectorXd & q,
      const Eigen::VectorXd & v,
      const Eigen::VectorXd & tau,
      const ForceVector * fext);

    ///
    /// \brief Project q onto the loops (Gauss-Newton, least norm) and v onto the motions they
    /// allow at the projected q (orthogonal projection in joint coordinates).
    ///
    /// \param[in] pinned Indices in v of 1-DoF joints held where they are (joints on a stop:
    ///            their q and v do not change), or nullptr.
    /// \return The largest constraint error left (m or rad).
    ///
    double project(
      pinocchio::Data & data,
      Eigen::VectorXd & q,
      Eigen::VectorXd & v,
      const std::vector<Eigen::Index> * pinned = nullptr);

  private:
    // With couplings and loops: the loops' constraint on the reduced acceleration.
    void loopAcceleration(
      pinocchio::Data & data, const Eigen::VectorXd & q, const Eigen::VectorXd & v);

    struct Impl;
    std::unique_ptr<Impl> impl_;
  };

} // namespace pinsettle

#endif // ifndef __pinsettle_loop_stepper_hpp__
