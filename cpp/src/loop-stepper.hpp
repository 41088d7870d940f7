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
    ///            their q and v do not change), or nullptr. If they hold the loops open, and
    ///            stops were given (useStops), those the loops pull into their range leave
    ///            their stop.
    /// \return The largest constraint error left (m or rad).
    ///
    double project(
      pinocchio::Data & data,
      Eigen::VectorXd & q,
      Eigen::VectorXd & v,
      const std::vector<Eigen::Index> * pinned = nullptr);

    /// \brief The stops of the run (or nullptr): see project().
    void useStops(const JointStops * stops);

    ///
    /// \brief Keep the velocity with which a step arrives, before the stops act on it: the
    /// velocity impact() starts from.
    ///
    /// \param[in] v Joint velocity (dim model.nv).
    ///
    void arrive(const Eigen::VectorXd & v);

    ///
    /// \brief An inelastic impact of joints on their stops in the closed mechanism: q onto the
    /// loops with the pinned joints held (as project()), and v the velocity nearest to the one
    /// given to arrive() in the metric of the mass matrix among those the loops allow with the
    /// pinned joints still. That is the velocity after an impulse through the stops and the
    /// loops, and it never has more kinetic energy than the arriving one (a projection in joint
    /// coordinates may: a light joint's speed handed to a heavy base).
    ///
    /// \param[in] pinned Indices in v of the joints on a stop (1-DoF joints).
    /// \return The largest constraint error left (m or rad).
    ///
    double impact(
      pinocchio::Data & data,
      Eigen::VectorXd & q,
      Eigen::VectorXd & v,
      const std::vector<Eigen::Index> & pinned);

    /// Constraint error (m or rad) above which the loops are open: the rest is no rest.
    static constexpr double kLoopTolerance = 1e-10;

  private:
    // q onto the loops with the pinned joints held (or released, see project()): the error
    // left, and the joints kept still (pinned, the held ones if released, or nullptr).
    struct ClosedLoops
    {
      double left;
      const std::vector<Eigen::Index> * still;
    };
    ClosedLoops closeLoops(
      pinocchio::Data & data, Eigen::VectorXd & q, const std::vector<Eigen::Index> * pinned);

    // With couplings and loops: the loops' constraint on the reduced acceleration.
    void loopAcceleration(
      pinocchio::Data & data, const Eigen::VectorXd & q, const Eigen::VectorXd & v);

    struct Impl;
    std::unique_ptr<Impl> impl_;
  };

} // namespace pinsettle

#endif // ifndef __pinsettle_loop_stepper_hpp__
